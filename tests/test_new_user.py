"""What a new user tripped on (issue 16, item 6), and the import cycle between the two evaluation
modules: each test here fails on the code before the fix (the reason is in its docstring where it
is not plain). The tests that write output paths run as root too (CI runs as root)."""

from __future__ import annotations

import ast
import dataclasses
import io
import json
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cli import build_parser, main
from hrc_drake.cli import tasks as task_commands
from hrc_drake.evaluate import evaluate
from hrc_drake.evaluation_report import summarise
from hrc_drake.evaluation_runs import RunResult, Setup
from hrc_drake.paths import UsageError, check_output_path
from hrc_drake.progress import ProgressLine
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.tasks.costs import save_cost_table
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.spec import load_spec

REPO = Path(__file__).resolve().parent.parent
TEN_SLOT = Path(__file__).parent / "data" / "ten-slot.yaml"
FOUR_SLOT = REPO / "models" / "assemblies" / "four-slot.yaml"


class NoWork(AssertionError):
    """Raised by a stand-in for the expensive step a command must not reach."""


def _no_work(*args, **kwargs):
    raise NoWork("the command went on to the work it should have refused before")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(code, err, command, *words):
    assert code == 2, (code, err)
    assert err.startswith(f"hrc-drake {command}: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, (word, err)


# --- 1. Output paths ---------------------------------------------------------------------------


def _special_file(path: Path) -> int:
    """A character device like /dev/null (as root) or a named pipe; its file type."""
    if os.geteuid() == 0:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    else:
        os.mkfifo(path)
    return stat.S_IFMT(os.stat(path).st_mode)


def test_an_output_path_on_a_device_or_pipe_is_refused_and_left_as_it_is(capsys, tmp_path):
    """Before: `solve --out NODE` replaced the node by a regular file."""
    node = tmp_path / "x"
    kind = _special_file(node)
    code, out, err = run(capsys, "solve", "--out", node)
    one_line_error(code, err, "solve", "--out", "not a regular file")
    assert out == "" and stat.S_IFMT(os.stat(node).st_mode) == kind
    with pytest.raises(OSError, match="not a regular file"):
        atomic_write_text(node, "{}")  # the last guard, for writers that skip the check
    assert stat.S_IFMT(os.stat(node).st_mode) == kind


def test_dev_null_is_refused_as_an_output_path():
    # Only the check: a writer that skipped it must not be run against the real /dev/null.
    with pytest.raises(UsageError, match="character device"):
        check_output_path("/dev/null", "--record")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


@pytest.mark.parametrize("folder", ["/proc", "/sys", "/sys/kernel"])
def test_an_output_path_where_no_file_can_be_made_fails_before_any_work(
    capsys, monkeypatch, folder
):
    """Before, as root: os.access said yes, the policy was solved, and writing it failed with a
    traceback. A probe file is now made and removed instead."""
    if not Path(folder).is_dir():
        pytest.skip(f"{folder} is not mounted here")
    monkeypatch.setattr(task_commands, "exact_policy", _no_work)
    code, out, err = run(capsys, "solve", "--out", f"{folder}/policy.json")
    one_line_error(code, err, "solve", f"--out {folder}/policy.json")
    assert "no file can be created" in err or "not writable" in err
    assert out == ""


def test_the_probe_leaves_nothing_behind(tmp_path):
    check_output_path(tmp_path / "out.json", "--out")
    assert list(tmp_path.iterdir()) == []


# --- 2. Scenario values of the wrong type ------------------------------------------------------

WRONG_TYPES = [
    ("{operator: {deviations: [{step: one, task: F1}]}}", "operator.deviations[0].step", "whole"),
    ('{motion: {hold_time: "5s"}}', "motion.hold_time", "expected a number"),
]


@pytest.mark.parametrize(("text", "key", "expected"), WRONG_TYPES)
def test_a_scenario_value_of_the_wrong_type_is_one_line_before_any_work(
    capsys, monkeypatch, tmp_path, text, key, expected
):
    """Before: Drake's converter raised a ValueError that ended in a 40-line traceback."""
    from hrc_drake.cell.run import costs
    from hrc_drake.cli import simulate as command

    monkeypatch.setattr(command, "run_scenario", _no_work)
    monkeypatch.setattr(costs, "default_cost_table", _no_work)
    code, _, err = run(capsys, "simulate", "--scenario-text", text)
    one_line_error(code, err, "simulate", "--scenario-text", key, expected)
    scenario = tmp_path / "mine.yaml"
    scenario.write_text(text + "\n")
    code, _, err = run(capsys, "simulate", "--scenario", scenario)
    one_line_error(code, err, "simulate", f"scenario {scenario}: {key}", expected)
    evaluate_cell = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--cell"]
    code, _, err = run(capsys, *evaluate_cell, "--runs", "1", "--scenario-text", text)
    one_line_error(code, err, "evaluate", "--scenario-text", key, expected)


def test_exponent_numbers_are_numbers_in_both_loaders():
    from hrc_drake.cell.scenario import load_cell_scenario, plant_step

    assert load_scenario(None, "{run: {period: 2e-2}}").run.period == 2e-2
    text = "{plant_config: {time_step: 1e-3}}"
    assert plant_step(load_cell_scenario(None, text)) == 1e-3


# --- 3. An assembly the UR3 cannot reach -------------------------------------------------------


def _suggested_cell(message: str) -> dict:
    found = re.search(r"the reach check passes with (cell: \{.*?\})", message)
    assert found, message
    return yaml.safe_load(found.group(1))["cell"]


def _with_cell(spec_text: str, cell: dict, path: Path) -> Path:
    path.write_text(spec_text + "cell: " + json.dumps(cell) + "\n")
    return path


def _reaches(spec_path: Path) -> bool:
    from hrc_drake.cell_models import CellDesign, CellModelError
    from hrc_drake.motion.planner import MotionPlanner
    from hrc_drake.motion.reach_check import check_reach

    try:
        check_reach(MotionPlanner(design=CellDesign.of(load_spec(spec_path))), suggest=False)
    except CellModelError:
        return False
    return True


def test_an_unreachable_assembly_is_the_same_one_line_everywhere_with_a_checked_layout(
    capsys, monkeypatch, tmp_path
):
    """Before: `costs` and `evaluate` ended in a CostPlanningError traceback; `simulate`
    suggested `cell.slot_pitch`, which does not fix a ten-slot base."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    commands = {
        "costs": ["--out", tmp_path / "costs.json"],
        "evaluate": ["--decider", "exact", "--operator-model", "follows", "--runs", "1"],
        "simulate": ["--lean"],
    }
    messages = set()
    for command, argv in commands.items():
        code, _, err = run(capsys, command, "--assembly", TEN_SLOT, *argv)
        one_line_error(code, err, command, "the UR3 cannot reach", "reach check passes with")
        messages.add(err.split(": error: ", 1)[1])
    assert len(messages) == 1
    (message,) = messages
    assert "slot_pitch (" not in message  # the old, unchecked hint
    assert not (tmp_path / "costs.json").exists()
    fixed = _with_cell(TEN_SLOT.read_text(), _suggested_cell(message), tmp_path / "fixed.yaml")
    assert not _reaches(TEN_SLOT) and _reaches(fixed)


def test_a_plate_out_of_reach_gets_a_checked_plate_layout(tmp_path):
    from hrc_drake.cell_models import CellDesign, CellModelError
    from hrc_drake.motion.planner import MotionPlanner
    from hrc_drake.motion.reach_check import check_reach

    flange = (REPO / "models" / "assemblies" / "flange.yaml").read_text()
    far = _with_cell(
        flange,
        {"plate_position": [0.30, 0.35, 0.0], "tray_position": [0.2, -0.25, 0.0]},
        tmp_path / "far.yaml",
    )
    with pytest.raises(CellModelError, match=r"cannot reach F3 \(slot 3\)") as err:
        check_reach(MotionPlanner(design=CellDesign.of(load_spec(far))))
    suggested = _suggested_cell(str(err.value))
    assert "plate_position" in suggested or "slot_pitch" in suggested
    cell = {"plate_position": [0.30, 0.35, 0.0], "tray_position": [0.2, -0.25, 0.0], **suggested}
    assert _reaches(_with_cell(flange, cell, tmp_path / "moved.yaml"))


@pytest.mark.slow
def test_the_suggested_layout_runs_in_the_cell(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    code, _, err = run(capsys, "simulate", "--assembly", TEN_SLOT, "--lean")
    fixed = _with_cell(TEN_SLOT.read_text(), _suggested_cell(err), tmp_path / "fixed.yaml")
    code, out, err = run(capsys, "simulate", "--assembly", fixed, "--lean", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result["terminal"] and result["final_kind"] == "terminal" and not result["collisions"]


# --- 4. table2 on another spec, and its note ---------------------------------------------------


def test_table2_refuses_another_spec(capsys):
    """Before: exit 0 with the flange's rows applied to the four-slot spec."""
    code, out, err = run(capsys, "table2", "--assembly", FOUR_SLOT)
    one_line_error(code, err, "table2", "Table 2 belongs to the flange case", "'four-slot'")
    assert out == ""


def test_table2_script_na_note_is_a_whole_sentence(capsys, tmp_path, flange_space):
    from test_cli import _policy_file

    path = _policy_file(flange_space, tmp_path, **{"": "S12", "F3": "undo"})
    code, out, _ = run(capsys, "table2", "--policy", path, "--json")
    note = {r["row"]: r for r in json.loads(out)}[7]["note"]
    assert code == 0 and note == (
        "script n/a: the row's F02 at step 3 is not feasible in state 13, which this policy's "
        "route reaches at that step"
    )


# --- 5. simulate --operator: the header says what will run -------------------------------------


def test_simulate_with_an_operator_script_describes_that_operator():
    """Before: the header showed row1's description, "nothing: the operator follows the robot"."""
    from hrc_drake.cli.scenario_args import scenario_from_args

    args = build_parser().parse_args(["simulate", "--operator", "1:F3,2:S12"])
    description = scenario_from_args(args).description
    assert "F3 at step 1, S12 at step 2 instead of the robot's proposal" in description
    assert "nothing" not in description


# --- 6. YAML syntax errors ---------------------------------------------------------------------


def test_a_yaml_syntax_error_names_the_file_line_and_column(capsys, monkeypatch, tmp_path):
    """Before: PyYAML's four lines about `<unicode string>`."""
    from hrc_drake.cli import simulate as command

    monkeypatch.setattr(command, "run_scenario", _no_work)
    spec = tmp_path / "bad.yaml"
    spec.write_text("name: x\nbase: {symbol: B, slots: 3\nparts: [\n")
    code, _, err = run(capsys, "states", "--assembly", spec)
    one_line_error(code, err, "states", f"{spec}, line 3, column 6: bad YAML: expected ','")
    assert "unicode string" not in err
    scenario = tmp_path / "bad-scenario.yaml"
    scenario.write_text("operator:\n  deviations: [{step: 1, task: F1}\n")
    code, _, err = run(capsys, "simulate", "--scenario", scenario)
    one_line_error(code, err, "simulate", f"scenario {scenario}, line 3, column 1: bad YAML")
    code, _, err = run(capsys, "simulate", "--scenario-text", "{motion: {hold_time: 1}")
    one_line_error(code, err, "simulate", "--scenario-text, line 1, column")


# --- 7. evaluate: progress, estimates, workers; simulate --still-time --------------------------


def test_the_first_evaluation_of_a_spec_shows_progress_while_it_plans_the_cost_table(
    capsys, monkeypatch, tmp_path, toy_costs
):
    """Before: `default_cost_table` got no progress callback: 10-18 s of silence."""
    from hrc_drake.cell.run import costs

    def compute(space, planner, progress):
        for i in range(1, len(toy_costs.entries) + 1):
            progress(i, len(toy_costs.entries), 10.0)
        return dataclasses.replace(toy_costs, cell_hash=costs.cell_hash(planner))

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setattr(costs, "compute_cost_table", compute)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--runs", "2"]
    code, _, err = run(capsys, *argv)
    assert code == 0
    plans = len(toy_costs.entries)  # the task edges here; a planned table has its bets too
    assert "cost table of flange" in err and f"plan {plans}/{plans}" in err
    code, _, err = run(capsys, *argv)  # cached now: nothing to plan
    assert code == 0 and "cost table" not in err


def test_still_time_is_checked_before_the_run(capsys, monkeypatch, tmp_path):
    """Before: a --still-time past the end was refused only after the whole run."""
    from hrc_drake.cli import simulate as command

    monkeypatch.setattr(command, "run_scenario", _no_work)
    still = ["simulate", "--lean", "--still", tmp_path / "still.png", "--still-time"]
    code, _, err = run(capsys, *still, "1000")
    one_line_error(code, err, "simulate", "past the end of the run", "900")
    with pytest.raises(NoWork):  # within the three holds: surely within the run, nothing said
        run(capsys, *still, "1.0")
    assert "note" not in capsys.readouterr().err
    with pytest.raises(NoWork):  # unknown until the end: said at once, before the run
        run(capsys, *still, "60")
    assert "known only when it ends" in capsys.readouterr().err


def test_too_many_cell_runs_are_refused_with_an_estimate_before_any_work(capsys, monkeypatch):
    from hrc_drake.cell.run import costs

    monkeypatch.setattr(costs, "default_cost_table", _no_work)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--cell"]
    code, _, err = run(capsys, *argv, "--runs", "100000")
    one_line_error(code, err, "evaluate", "--runs 100000", "days", "at most 1000 cell runs")


def test_cell_runs_start_with_an_estimate(capsys, monkeypatch, toy_costs):
    from hrc_drake.cell.run import costs
    from hrc_drake.cli import evaluate as evaluate_command

    monkeypatch.setattr(costs, "default_cost_table", lambda space, progress=None: toy_costs)
    monkeypatch.setattr(evaluate_command, "evaluate", _no_work)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--cell", "--lean"]
    with pytest.raises(NoWork):
        run(capsys, *argv, "--runs", "4")
    err = capsys.readouterr().err
    # Three tasks (no robot times in the toy table: the typical 6.4 s), 0.5 s holds, 0.2 s
    # settling, and the pointer's mean indication delay (2.09 s) the cell's robot waits for.
    assert "evaluate --cell: 4 run(s), about 28 s simulated per run" in err


def test_workers_are_capped_at_the_cpus_with_a_note(capsys, tmp_path, toy_costs):
    from hrc_drake.cli.evaluate import usable_cpus

    save_cost_table(toy_costs, tmp_path / "costs.json")
    code, out, err = run(
        capsys,
        "evaluate",
        "--decider",
        "exact",
        "--operator-model",
        "follows",
        "--runs",
        "6",
        "--workers",
        "64",
        "--costs",
        tmp_path / "costs.json",
        "--json",
    )
    used = min(usable_cpus(), 6)
    assert code == 0 and json.loads(out)["workers"] == used
    assert "note: --workers 64: " in err and f"; using {used}" in err


def test_the_progress_line_always_shows_the_last_update():
    """Before: an update within `interval` of the previous one was dropped, the last too, so two
    cell runs ending together left the line at "run 1/2"."""
    stream = io.StringIO()
    line = ProgressLine("cell", "run", interval=60.0, stream=stream)
    line.update(1, 2)
    line.update(2, 2)
    assert "run 1/2" in stream.getvalue() and "run 2/2" in stream.getvalue()


@dataclasses.dataclass(frozen=True)
class InstantCell:
    """A stand-in for the cell (`hrc_drake.evaluation_runs.CellRuns`): a run of `tasks` tasks at
    once."""

    seconds: float = 30.0

    def prepare(self, space):
        return space.spec.name

    def check(self, operator, model_name):
        pass

    def play(self, prepared, setup, decider, run):
        return RunResult(True, self.seconds, 3, 0, 0, (0.0,) * 3, (True,) * 3)

    def replay(self, setup, run):
        return None

    def describe(self, space):
        return {"scenario": f"instant {space.spec.name}"}

    def playing(self, mode):
        return self


def test_cell_runs_over_processes_report_every_run(flange_space, toy_costs):
    """The task-level evaluation plays cell runs through `Setup.cell` alone (before, it imported
    the cell module and could not take another player), one run per chunk in processes, so
    that the progress counts every run."""
    setup = Setup(flange_space, toy_costs, "exact", "follows", {}, 0, cell=InstantCell())
    seen = []
    report = evaluate(setup, 3, 2, progress=lambda done, total: seen.append((done, total)))
    assert seen == [(1, 3), (2, 3), (3, 3)]
    assert report["completed"] == 3 and report["scenario"] == "instant flange"


def test_a_cell_report_says_what_ran(flange_space):
    """Before: `"scenario": "row1-optimal"` whatever the spec."""
    from hrc_drake.cell.run.evaluate import CellOptions

    four = generate_states(load_spec(FOUR_SLOT))
    result = RunResult(True, 30.0, 3, 0, 0)
    report = summarise(Setup(four, None, "exact", "follows", {}, 0, cell=CellOptions()), [result])
    assert report["scenario"].startswith("row1-optimal with assembly four-slot")
    assert report["base_scenario"] == "row1-optimal" and report["scenario_overrides"] == []
    flange = Setup(flange_space, None, "exact", "follows", {}, 0, cell=CellOptions())
    report = summarise(flange, [result])
    assert report["scenario"] == "row1-optimal with its operator from the population model"


# --- The import cycle --------------------------------------------------------------------------


def _imports(path: Path) -> set[str]:
    """Every module a file imports, at the top or inside functions."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_the_evaluation_modules_depend_one_way():
    task_level = _imports(REPO / "hrc_drake" / "evaluate.py")
    cell_level = _imports(REPO / "hrc_drake" / "cell" / "run" / "evaluate.py")
    assert not [m for m in task_level if m.startswith("hrc_drake.cell")], task_level
    assert "hrc_drake.evaluate" in cell_level
    assert "hrc_drake.cli.evaluate" not in cell_level


def test_the_evaluate_command_line_imports_no_drake():
    code = (
        "import sys, hrc_drake.cli, hrc_drake.cli.evaluate\n"
        "hrc_drake.cli.build_parser()\n"
        "print(any(m.startswith('pydrake') for m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "False", done.stderr


# --- 8. Docs -----------------------------------------------------------------------------------

SPEC_DOC = REPO / "docs" / "spec.md"


def _yaml_blocks(text: str) -> list[str]:
    return re.findall(r"```yaml\n(.*?)```", text, re.S)


def _spec_keys() -> set[str]:
    """The keys `parse_spec` allows, read from its `_check_keys(..., {...})` calls."""
    source = (REPO / "hrc_drake" / "tasks" / "spec.py").read_text()
    keys = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "_check_keys":
            for arg in node.args:
                if isinstance(arg, ast.Set):
                    keys.update(e.value for e in arg.elts if isinstance(e, ast.Constant))
    return keys


def test_the_spec_reference_names_every_key_and_its_example_loads(tmp_path):
    text = SPEC_DOC.read_text()
    keys = _spec_keys()
    assert {"name", "base", "mounts", "complete_first", "min_gap", "bolt_time"} <= keys
    assert not [k for k in keys if f"`{k}" not in text]
    example = tmp_path / "example.yaml"
    example.write_text(_yaml_blocks(text)[0])
    spec = load_spec(example)
    assert spec.name == "five-slot" and spec.cell is not None


def test_the_spec_reference_says_one_oval_per_square_with_two_host_types(tmp_path):
    snippet = yaml.safe_load(_yaml_blocks(SPEC_DOC.read_text())[1])
    data = {"name": "two-squares", "base": {"slots": 5}, "goal": {"min_gap": []}, **snippet}
    data["goal"] = {"min_gap": [{"parts": ["F", "F"], "slots": 1}]}
    path = tmp_path / "two.yaml"
    path.write_text(yaml.safe_dump(data))
    space = generate_states(load_spec(path))
    terminal = [s for s in range(space.n_states) if space.kind[s] == StateKind.TERMINAL]
    finished = [space.configuration(s) for s in terminal]
    assert finished
    for configuration in finished:  # one oval flange on each square, in every finished state
        on_s = [t for t in configuration if re.fullmatch(r"F0\d", t)]
        on_t = [t for t in configuration if re.fullmatch(r"F1\d", t)]
        assert len(on_s) == 1 and len(on_t) == 1, configuration


def test_the_readme_wrong_type_example_is_one():
    readme = (REPO / "README.md").read_text()
    found = re.search(r"a value of the wrong type\s*\(`([^`]+)`\)", readme)
    assert found, "the README's example of a value of the wrong type"
    with pytest.raises(ScenarioError, match="expected a whole number"):
        load_scenario(None, "{" + found.group(1) + "}")


def test_the_readme_says_how_to_run_each_example():
    readme = (REPO / "README.md").read_text()
    for example in sorted((REPO / "examples").glob("*.py")):
        assert f".venv/bin/python examples/{example.name}" in readme, example.name


def test_the_evaluation_figure_has_every_decider_on_linear_axes(monkeypatch, tmp_path):
    """Before: a log axis and no `exact` (docs/evaluation.png, benchmarks/bench_evaluate.py)."""
    import importlib.util

    from hrc_drake.tasks import plots

    figures = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path, dpi=120: figures.append(fig))
    monkeypatch.syspath_prepend(str(REPO / "benchmarks"))
    path = REPO / "benchmarks" / "bench_evaluate.py"
    spec = importlib.util.spec_from_file_location("bench_evaluate", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    from hrc_drake.tasks.deciders import DECIDERS

    table = {
        (d, m): {"mean_time": 34.0 + k, "p95_time": 40.0 + k}
        for k, d in enumerate(DECIDERS)
        for m in bench.MODELS
    }
    bench.plot_means(table, tmp_path / "evaluation.png")
    (fig,) = figures
    assert all(ax.get_xscale() == "linear" and ax.get_yscale() == "linear" for ax in fig.axes)
    labels = {t.get_text() for ax in fig.axes for t in ax.get_yticklabels()}
    assert "exact" in labels and set(DECIDERS) <= labels
    shown = {t.get_text() for ax in fig.axes for t in ax.texts}
    assert "34.00" in shown and "38.00" in shown  # values printed beside their dots
