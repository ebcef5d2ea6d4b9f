"""The catalogue and the operator populations through the cell: every scenario file runs lean to
its terminal state with no robot collision, and a sweep of the cell across every population ends
each run terminal (or by the run's own task cap, with its reason) with no collision."""

import json

import pytest
from cell_checks import check_catalogue_run

from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cli import main
from hrc_drake.hri.populations import OPERATOR_MODELS
from hrc_drake.resources import scenarios_dir
from hrc_drake.scenario.load import table2_scenarios
from hrc_drake.tasks.decide import run_decisions
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import load_spec

pytestmark = pytest.mark.slow

CATALOGUE = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))
# The rows of Table 2 run lean in tests/test_closed_loop.py, with the states the spec gives
# them; every other file runs here.
ROWS = {row.name for row in table2_scenarios()}
# Files with a test of their own below, which makes the same checks and more.
OWN_TESTS = {"stochastic-mistakes"}
OTHERS = [name for name in CATALOGUE if name not in ROWS | OWN_TESTS]
# The built-in operator populations (`hrc_drake.hri.populations`).
POPULATIONS = ("follows", "random", "habitual", "mistake-prone", "change-of-mind", "slow")


def test_the_catalogue_is_covered():
    """Every scenario file is run to its end by a test: the rows there, the others here."""
    assert ROWS and OTHERS
    assert set(CATALOGUE) == ROWS | OWN_TESTS | set(OTHERS)
    assert set(POPULATIONS) <= set(OPERATOR_MODELS)


@pytest.mark.parametrize("name", OTHERS)
def test_every_other_catalogue_scenario_runs_lean_to_its_terminal_state(name):
    check_catalogue_run(name, run_scenario(load_cell_scenario(name, LEAN)))


def test_a_stochastic_operator_misplaces_and_the_cell_follows_the_decision_loop():
    """stochastic-mistakes: the operator's wrong row is seen from contact, and the physical run
    visits the states the decision loop predicts for the same seed."""
    space = generate_states(load_spec())
    scenario = load_cell_scenario("stochastic-mistakes", LEAN)
    result = run_scenario(scenario)
    check_catalogue_run("stochastic-mistakes", result)
    terminal = {
        space.configuration(s) for s in range(space.n_states) if space.kind[s] == StateKind.TERMINAL
    }
    assert result.final_tokens in terminal
    deviations = [t for t in result.tasks if t.indicated != t.proposed]
    assert any(t.observed in {"F01", "F02", "F03"} for t in deviations), "no misplaced flange"
    predicted, _ = run_decisions(space, exact_policy(space), scenario.operator_for(space))
    assert result.states == predicted


def test_a_run_past_its_task_cap_ends_with_the_reason_and_is_no_failure():
    """An operator who keeps undoing can outlast any cap: the run ends there with the reason,
    capped, and the evaluation does not count it as a failure."""
    scenario = load_cell_scenario("row3-forces-3", [LEAN, "{run: {max_steps: 1}}"])
    result = run_scenario(scenario)
    assert not result.done and result.capped
    assert "run.max_steps" in result.error
    assert result.to_json()["capped"] is True


@pytest.mark.parametrize("model", POPULATIONS)
def test_the_cell_holds_up_against_every_operator_population(model, capsys):
    """A short sweep of the cell, one run of each population (the benchmark
    `bench_population_sweep` runs the long one): it ends terminal or by its task cap, and does
    not collide or break separation."""
    code = main(
        [
            "evaluate",
            "--cell",
            "--lean",
            "--decider",
            "exact",
            "--operator-model",
            model,
            "--runs",
            "1",
            "--json",
        ]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["runs"] == 1
    assert report["completed"] + report["capped"] == 1
    assert report["collisions"] == 0
    assert report["failures"] == []


def test_a_slow_operator_bolts_longer_along_the_run_and_the_robot_holds_on():
    """The `slow` population in the cell: its bolting time grows by `growth` each step, and the
    robot holds each part until the operator says it is bolted."""

    def held(model: str) -> list[float]:
        text = f"{{operator: {{model: {model}, seed: 0, params: {{growth: 2.0}}}}}}"
        if model == "follows":
            text = "{operator: {model: follows, seed: 0}}"
        result = run_scenario(load_cell_scenario("row1-optimal", [LEAN, text]))
        assert result.done and result.collisions == []
        return [t.end_time - t.held_at for t in result.tasks]

    slow, follows = held("slow"), held("follows")
    hold = load_cell_scenario("row1-optimal", LEAN).motion.hold_time
    # Step k bolts (1 + 2 (k - 1)) holds: 0, 2 and 4 holds longer than the follower's.
    for step, (s, f) in enumerate(zip(slow, follows, strict=True)):
        assert s - f == pytest.approx(2.0 * step * hold, abs=0.1)
