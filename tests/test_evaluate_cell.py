"""`hrc-drake evaluate --cell` and `--ray`: deciders against operator populations through the
physical cell, and runs spread on Ray.

The cell runs use lean settings (short holds); a hand-made cost table keeps the deciders free
of motion planning before the runs.
"""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np
import pytest

from hrc_drake.cell.run.evaluate import CellOptions, DeciderPolicy
from hrc_drake.cell.scenario import LEAN
from hrc_drake.cli import main
from hrc_drake.evaluate import _play, _prepare, evaluate
from hrc_drake.evaluation_report import summarise
from hrc_drake.evaluation_runs import Setup
from hrc_drake.paths import UsageError
from hrc_drake.resources import models_dir
from hrc_drake.tasks.deciders import make_decider
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.interaction import ANTICIPATE, WAIT, make_interaction
from hrc_drake.tasks.policy import PolicyFileError
from hrc_drake.tasks.spec import load_spec

# Seed 2 of mpc against a mistake-prone operator (p = 0.5): run 0 follows (3 tasks), run 1
# misplaces a flange once, which the robot takes back (5 tasks).
SEED = 2
NO_BODY = "{body: {enabled: false}}"  # faster; the operator's body is tested elsewhere


def _keys(report, *names):
    return {k: report[k] for k in names}


DECISIONS = ("runs", "completed", "completion_rate", "mean_tasks", "mean_undos", "mean_deviations")


INTERACTION = ("interaction", "commit_rate", "mean_retargets", "mean_swaps")


@pytest.fixture(scope="module")
def played(flange_space, toy_costs):
    """mode -> (the cell's Setup, the task level's report, the cell's report) of mpc against a
    mistake-prone operator, two seeded runs; each mode is played once for the module."""
    reports = {}

    def play(mode: str):
        if mode not in reports:
            interaction = make_interaction(mode)
            task = Setup(flange_space, toy_costs, "mpc", "mistake-prone", {"p": "0.5"}, SEED)
            task = dataclasses.replace(task, interaction=interaction)
            cell = dataclasses.replace(task, cell=CellOptions(overrides=(LEAN, NO_BODY)))
            reports[mode] = cell, evaluate(task, 2), evaluate(cell, 2)
        return reports[mode]

    return play


@pytest.mark.slow
def test_cell_runs_play_the_task_level_runs_and_are_independent(played):
    # `wait`: the robot waits for each indication, at task level and in the cell.
    cell, expected, report = played(WAIT)
    assert expected["mean_deviations"] == 0.5  # the seed does exercise a mistake
    # The cell observes what the operator did, the decider learns from it, and the decisions
    # are those of the task level, run for run.
    assert _keys(report, *DECISIONS) == _keys(expected, *DECISIONS)
    assert report["level"] == "cell" and report["collisions"] == 0 and report["errors"] == []
    assert report["failures"] == [] and report["interrupted"] is False  # every run passed
    assert report["handovers"] == 0 and report["runs_with_handovers"] == 0  # no task handed over
    assert _keys(report, *INTERACTION) == _keys(expected, *INTERACTION)
    assert report["interaction"] == WAIT and report["commit_rate"] == 0.0
    # The simulated operator waited the delays the task level drew for the same runs.
    assert report["mean_indication_delay"] == expected["mean_indication_delay"] > 3.0
    # Simulated seconds of the cell: three lean tasks take well over 15 s, five over 25 s, and
    # before each the robot waits for the indication (the pointer's delay, about 2 s).
    assert 20.0 < min(report["times"]) < 35.0 < max(report["times"]) < 75.0
    assert 0.0 <= report["plan_ready_rate"] <= 1.0 and report["mean_idle"] >= 0.0
    # Idle in simulated seconds: one Supervisor update (20 ms) a boundary, the planner's wall
    # time apart, so the report does not depend on the machine.
    assert report["mean_idle"] == pytest.approx(0.02) and report["wall_mean_idle"] >= 0.0
    # Run 0 played again after run 1 gives what it gave first, in a fresh process state: runs
    # share no plans and no decider memory (run 1's mistake and undo would have left some), so
    # the way runs are spread does not change the report.
    _prepare(cell)
    alone = summarise(cell, [_play(0)])
    assert alone["times"] == report["times"][:1]
    assert alone["mean_tasks"] == 3.0 and alone["mean_undos"] == 0.0


@pytest.mark.slow
def test_cell_runs_anticipate_as_the_task_level_does(played):
    # `anticipate`: at each boundary the decider bets (or waits) in the cell as at task level,
    # and the cell re-targets or swaps where the task level's timeline does.
    _cell, expected, report = played(ANTICIPATE)
    assert _keys(report, *DECISIONS) == _keys(expected, *DECISIONS)
    assert _keys(report, *INTERACTION) == _keys(expected, *INTERACTION)
    assert report["interaction"] == ANTICIPATE and report["commit_rate"] > 0.5
    assert report["collisions"] == 0 and report["errors"] == []
    assert report["mean_indication_delay"] == expected["mean_indication_delay"]
    # The robot moves while the operator indicates: the runs are shorter than waiting's.
    _cell, _task, waited = played(WAIT)
    for anticipating, waiting in zip(report["times"], waited["times"], strict=True):
        assert anticipating < waiting - 1.0


def test_decider_policy_proposes_predicts_and_learns(flange_space, toy_costs):
    # The cell's robot waits for the indication: the decider prices waiting.
    decider = make_decider("mpc", flange_space, toy_costs, interaction=make_interaction(WAIT))
    policy = DeciderPolicy(decider, flange_space)
    policy.matches(flange_space.spec)
    first = policy.next_task(())
    assert policy.predicted_tasks(()) == [first]  # nothing learned: the proposal only
    other = next(t for t, _ in flange_space.tasks(0) if t != first)

    @dataclasses.dataclass
    class Record:
        state: tuple
        proposed: str
        observed: str

    for _ in range(6):
        policy.observe(Record((), first, other))
    predicted = policy.predicted_tasks(())
    # After six overrides the model expects the operator's own choice more than its following
    # (its 4 pseudo-counts); planning ahead plans it (most likely first) besides what the robot
    # proposes.
    assert predicted[0] == other and policy.next_task(()) in predicted
    terminal = int(np.flatnonzero(flange_space.kind == StateKind.TERMINAL)[0])
    assert policy.next_task(flange_space.sequence(terminal)) is None
    two = generate_states(load_spec(models_dir() / "assemblies" / "four-slot.yaml"))
    with pytest.raises(PolicyFileError, match="made for assembly"):
        policy.matches(two.spec)


def test_cell_options_are_refused_without_cell(capsys):
    args = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--lean"]
    assert main(args) == 2
    assert "add --cell" in capsys.readouterr().err
    args = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--ray", "bad"]
    assert main(args) == 2
    assert "HOST:PORT" in capsys.readouterr().err


def test_ray_gives_the_serial_report(flange_space, toy_costs, capsys):
    pytest.importorskip("ray")
    setup = Setup(flange_space, toy_costs, "mpc", "mistake-prone", {"p": "0.3"}, 7)
    serial = evaluate(setup, 40)
    spread = evaluate(setup, 40, workers=2, ray=True)
    assert spread["backend"] == "ray" and spread["workers"] == 2
    same = [k for k in serial if not k.startswith("wall") and k not in ("workers", "backend")]
    assert _keys(spread, *same) == _keys(serial, *same)
    assert serial["mean_deviations"] > 0  # the runs differ from one another
    capsys.readouterr()
    json.dumps(spread)


def test_ray_missing_is_a_clear_error(flange_space, toy_costs, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    setup = Setup(flange_space, toy_costs, "exact", "follows", {}, 0)
    with pytest.raises(UsageError, match=r"pip install 'hrc_drake\[ray\]'"):
        evaluate(setup, 2, ray=True)


@pytest.mark.slow
def test_a_failing_cell_run_is_listed_and_replays_alone(tmp_path, toy_costs, capsys):
    """A cap on the simulated time that no run can finish within: the report lists each
    run, with the `simulate` command that gives its states and stop alone."""
    import shlex
    import subprocess

    from simulate_process import hrc_drake_command

    from hrc_drake.cli.evaluate import print_report
    from hrc_drake.evaluation_runs import run_seed
    from hrc_drake.tasks.costs import save_cost_table

    costs = tmp_path / "toy-costs.json"
    save_cost_table(toy_costs, costs)
    args = ["evaluate", "--cell", "--lean", "--runs", "2", "--seed", str(SEED), "--json"]
    args += ["--decider", "mpc", "--operator-model", "mistake-prone", "--param", "p=0.5"]
    args += ["--costs", str(costs), "--scenario-text", NO_BODY]
    # Two lean tasks take well over 10 s: each run stops within its second task.
    # A failing run fails the command, with one line on stderr.
    assert main([*args, "--scenario-text", "{run: {max_sim_time: 10}}"]) == 1
    out, err = capsys.readouterr()
    report = json.loads(out)
    assert err.strip().splitlines()[-1] == (
        "hrc-drake evaluate: 2 of 2 cell runs failed "
        "(each listed under failures, with the command that replays it)"
    )
    assert report["completed"] == 0
    assert [f["run"] for f in report["failures"]] == [0, 1]
    failure = report["failures"][1]
    assert failure["seed"] == run_seed(SEED, 1)
    assert failure["operator_model"] == "mistake-prone" and failure["params"] == {"p": 0.5}
    assert failure["stop"] == "no terminal state within 10.0 s of simulated time"
    assert len(failure["states"]) >= 2 and failure["collisions"] == 0
    command = shlex.split(failure["replay"])
    assert command[:2] == ["hrc-drake", "simulate"]
    replay = subprocess.run(
        [*hrc_drake_command(), *command[1:], "--json"], capture_output=True, text=True, timeout=600
    )
    assert replay.returncode == 1, replay.stderr[-500:]
    alone = json.loads(replay.stdout)
    assert alone["names"] == failure["states"] and alone["error"] == failure["stop"]
    assert alone["terminal"] is False
    # The text report names the run, why it stopped and its replay command.
    print_report(report)
    text = capsys.readouterr().out
    assert f"run 1 (mistake-prone p=0.5, seed {failure['seed']}): {failure['stop']}" in text
    assert f"replay: {failure['replay']}" in text


def test_a_run_fails_on_the_safety_check_not_on_a_permitted_approach(flange_space, toy_costs):
    """Steps inside S_p that power and force limiting permits are reported, not a failure; a
    step or contact beyond ISO/TS 15066 (the run's check failed) is one, with why."""
    from hrc_drake.evaluation_report import failures, stop_reason
    from hrc_drake.evaluation_runs import RunResult

    class Replays:
        def replay(self, setup, run):
            return f"hrc-drake simulate --run {run}"

    setup = Setup(flange_space, toy_costs, "exact", "follows", {}, 0, cell=Replays())
    permitted = RunResult(True, 40.0, 3, 0, 0, violations=12)
    beyond = dataclasses.replace(permitted, unsafe=2)
    listed = failures(setup, [permitted, beyond], [0, 1])
    assert [f["run"] for f in listed] == [1]
    assert listed[0]["separation_violations"] == 12 and listed[0]["beyond_iso_15066"] == 2
    assert stop_reason(beyond) == "2 step(s) or contact(s) beyond ISO/TS 15066"
