"""The one loader of scenarios, without Drake (the task layer and the cell alike): a file by
name or path, `--scenario-text` layered on the result as Drake's `hardware_sim` layers it, then
checked once (`hrc_drake.scenario.check`). It reads a file as Drake's `yaml_load_typed` would
(`tests/test_scenario_loader.py` compares them on every catalogue scenario), with one-line
errors where Drake's are a converter's traceback."""

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path

import yaml

from hrc_drake.hri.operator import parse_operator_script
from hrc_drake.paths import not_a_file
from hrc_drake.resources import scenarios_dir
from hrc_drake.scenario.check import check_finite, check_scenario
from hrc_drake.scenario.schema import (
    DRAKE_SECTIONS,
    TEXT_SOURCE,
    Deviation,
    DrakeSection,
    OperatorConfig,
    Scenario,
    ScenarioError,
)
from hrc_drake.typed_yaml import (
    TypedYamlError,
    dump_flow,
    load_tagged,
    load_typed,
    yaml_error_line,
)


def scenario_file(name_or_path: str | Path) -> Path:
    """The file of a scenario: a path, or a name under scenarios/; ScenarioError if missing, or
    if what is there is not a regular file (a folder, a device such as /dev/null, a pipe)."""
    path = Path(name_or_path)
    # A name without a suffix is a scenario of the catalogue, unless it is a path to something
    # that exists (`--scenario /bin/ls`): then say what that is, not "not found".
    if not path.suffix and not (os.sep in str(name_or_path) and path.exists()):
        path = scenarios_dir() / f"{name_or_path}.yaml"
    if path.exists() and not path.is_file():
        raise ScenarioError(
            f"scenario {name_or_path}: {not_a_file(path)}; give a scenario YAML file or the "
            "name of one in scenarios/"
        )
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenarios_dir().glob("*.yaml")))
        raise ScenarioError(f"scenario {name_or_path!r} not found; known scenarios: {known}")
    return path


def load_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """Load a scenario file (a path, or a name under scenarios/), then the YAML overrides in
    `scenario_text` (one text, or several applied in turn); with no file, the overrides on top
    of the defaults. Strict: ScenarioError naming the key and the expected type for an unknown
    key or a value of the wrong type, and the line and column of a YAML syntax error."""
    scenario, source = Scenario(), "<defaults>"
    if name_or_path is not None:
        path = scenario_file(name_or_path)
        source = str(path)
        scenario = _load_typed(_read_text(path), f"scenario {path}", None)
        if not scenario.name:
            scenario.name = path.stem
    texts = [scenario_text] if isinstance(scenario_text, str) else list(scenario_text or ())
    base = scenario
    for text in texts:
        scenario = _load_typed(text, "--scenario-text", scenario)
    if scenario is base:
        return check_scenario(scenario, source)
    return _check_overridden(base, scenario, source)


def _check_overridden(base: Scenario, scenario: Scenario, source: str) -> Scenario:
    """`check_scenario` of `scenario`, the file `base` with `--scenario-text` over it. A problem
    the file alone shows is the file's; any other came from the text, and the message names
    `--scenario-text` (the user looks there, not in a file they did not touch)."""
    try:
        return check_scenario(scenario, source)
    except ScenarioError as err:
        try:
            check_scenario(base, source)
        except ScenarioError as own:
            if str(own) == str(err):
                raise
        check_scenario(scenario, TEXT_SOURCE)  # the same problem, blamed on the text
        raise  # not reached: the check above raises the same problem


def _read_text(path: Path) -> str:
    """The text of the scenario file `path`; ScenarioError if it cannot be read or is not text
    (`--scenario /bin/ls`)."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(
            f"scenario {path}: not a text file (byte {err.object[err.start]:#04x} at offset "
            f"{err.start} is not UTF-8); give a scenario YAML file"
        ) from None
    except OSError as err:
        raise ScenarioError(
            f"scenario {path}: cannot be read ({err.strerror or err}); give a readable file"
        ) from None


def _load_typed(text: str, source: str, defaults: Scenario | None) -> Scenario:
    """`text` read onto `defaults`: the project's sections by the project's typed reader, the
    Drake sections (`DRAKE_SECTIONS`) kept as text for the cell, which reads them with Drake's
    own loader. The pre-pass (`load_tagged`) refuses a key given twice anywhere, and NaN or
    infinity in a Drake section (`check_finite`), which Drake's loader takes as numbers."""
    try:
        data = load_tagged(text)
    except yaml.YAMLError as err:
        raise ScenarioError(yaml_error_line(err, source)) from None
    drake = {}
    if isinstance(data, dict):
        drake = {key: data.pop(key) for key in DRAKE_SECTIONS if key in data}
        check_finite(drake, "", lambda key, problem: ScenarioError(f"{source}: {key}: {problem}"))
    try:
        scenario = load_typed(Scenario, data=data, defaults=defaults, source=source)
    except TypedYamlError as err:
        raise ScenarioError(f"{source}: {err}") from None
    given = [DrakeSection(source, key, dump_flow({key: value})) for key, value in drake.items()]
    scenario.drake = (list(defaults.drake) if defaults is not None else []) + given
    return scenario


def with_operator_script(scenario: Scenario, script: str) -> Scenario:
    """A copy whose operator follows the command-line script ``"1:F3,2:S12"``."""
    steps = parse_operator_script(script)
    operator = OperatorConfig(deviations=[Deviation(k, t) for k, t in sorted(steps.items())])
    return dataclasses.replace(scenario, operator=operator)


def table2_scenarios() -> list[Scenario]:
    """The scenarios that reproduce the rows of the paper's Table 2, in the table's order."""
    rows = [load_scenario(p) for p in sorted(scenarios_dir().glob("*.yaml"))]
    rows = [r for r in rows if r.table2_row is not None]
    return sorted(rows, key=lambda r: r.table2_row)


__all__ = ["load_scenario", "scenario_file", "table2_scenarios", "with_operator_script"]
