"""Operator scenarios as data files (`scenarios/*.yaml`): who deviates, when, and what to expect.

A scenario names the assembly, the operator (a script of overrides, or stochastic override and
mistake probabilities with a seed), and optionally its Table 2 row with the published and the
minimum-effort sequences (as the spec's state names).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from hrc_drake.hri.operator import (
    ScriptedOperator,
    StochasticOperator,
    parse_operator_script,
)
from hrc_drake.resources import models_dir, scenarios_dir
from hrc_drake.tasks.graph import StateSpace


class ScenarioError(ValueError):
    """A scenario file that cannot be used."""


@dataclass(frozen=True)
class OperatorScenario:
    """One operator scenario."""

    name: str
    description: str
    assembly: Path
    script: dict[int, str]
    override_prob: float = 0.0
    mistake_prob: float = 0.0
    seed: int = 0
    table2_row: int | None = None
    published: tuple[str, ...] = ()
    minimum_effort: tuple[str, ...] = ()

    @property
    def stochastic(self) -> bool:
        """Whether the operator deviates at random."""
        return self.override_prob > 0 or self.mistake_prob > 0

    def operator(self, space: StateSpace):
        """The operator this scenario describes, for the decision loop or the cell."""
        if self.stochastic:
            return StochasticOperator(space, self.override_prob, self.mistake_prob, self.seed)
        return ScriptedOperator(self.script)


_KEYS = {"name", "description", "assembly", "operator", "table2_row", "expected"}


def load_scenario(name_or_path: str | Path) -> OperatorScenario:
    """Load `scenarios/<name>.yaml` (or a path); ScenarioError naming the key if malformed."""
    path = Path(name_or_path)
    if not path.suffix:
        path = scenarios_dir() / f"{name_or_path}.yaml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenarios_dir().glob("*.yaml")))
        raise ScenarioError(f"scenario {name_or_path!r} not found; known scenarios: {known}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ScenarioError(f"scenario {path}: bad YAML: {err}") from err
    if not isinstance(data, dict):
        raise ScenarioError(f"scenario {path}: must be a mapping")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ScenarioError(
            f"scenario {path}: unknown key {unknown[0]!r}; keys are {sorted(_KEYS)}"
        )
    operator = data.get("operator") or {}
    op_keys = {"script", "override_prob", "mistake_prob", "seed"}
    if not isinstance(operator, dict) or set(operator) - op_keys:
        raise ScenarioError(f"scenario {path}: operator: allowed keys are {sorted(op_keys)}")
    try:
        script = parse_operator_script(str(operator.get("script", "")))
    except ValueError as err:
        raise ScenarioError(f"scenario {path}: operator.script: {err}") from err
    expected = data.get("expected") or {}
    assembly = data.get("assembly", "flange")
    assembly_path = Path(assembly)
    if not assembly_path.suffix:
        assembly_path = models_dir() / "assemblies" / f"{assembly}.yaml"
    return OperatorScenario(
        name=str(data.get("name", path.stem)),
        description=str(data.get("description", "")),
        assembly=assembly_path,
        script=script,
        override_prob=float(operator.get("override_prob", 0.0)),
        mistake_prob=float(operator.get("mistake_prob", 0.0)),
        seed=int(operator.get("seed", 0)),
        table2_row=data.get("table2_row"),
        published=tuple(str(s) for s in expected.get("published", ())),
        minimum_effort=tuple(str(s) for s in expected.get("minimum_effort", ())),
    )


def table2_scenarios() -> list[OperatorScenario]:
    """The scenarios that reproduce the rows of the paper's Table 2, in the table's order."""
    rows = [load_scenario(p) for p in sorted(scenarios_dir().glob("*.yaml"))]
    rows = [r for r in rows if r.table2_row is not None]
    return sorted(rows, key=lambda r: r.table2_row)
