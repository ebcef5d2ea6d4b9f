"""The catalogue and the operator populations through the cell: every scenario file runs lean to
its terminal state with no robot collision, and a sweep of the cell across every population ends
each run terminal (or by the run's own task cap, with its reason) with no collision."""

import json

import pytest

from hrc_drake.cell.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cli import main
from hrc_drake.hri.populations import OPERATOR_MODELS
from hrc_drake.hri.scenario import load_scenario, table2_scenarios
from hrc_drake.resources import scenarios_dir

pytestmark = pytest.mark.slow

CATALOGUE = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))
# The rows of Table 2 run lean in tests/test_closed_loop.py, with the states the spec gives
# them; every other file runs here.
ROWS = {row.name for row in table2_scenarios()}
OTHERS = [name for name in CATALOGUE if name not in ROWS]
# The built-in operator populations (`hrc_drake.hri.populations`).
POPULATIONS = ("follows", "random", "habitual", "mistake-prone", "change-of-mind", "slow")


def test_the_catalogue_is_covered():
    """Every scenario file is run to its end by a test: the rows there, the others here."""
    assert ROWS and OTHERS
    assert set(CATALOGUE) == ROWS | set(OTHERS)
    assert set(POPULATIONS) <= set(OPERATOR_MODELS)


@pytest.mark.parametrize("name", OTHERS)
def test_every_other_catalogue_scenario_runs_lean_to_its_terminal_state(name):
    result = run_scenario(load_cell_scenario(name, LEAN))
    assert result.error is None, result.error
    assert result.done and result.final_kind == "terminal"
    assert result.collisions == []
    if result.safety is not None:
        assert result.safety.violations == 0 and result.safety.body_contacts == 0
    expected = load_scenario(name).minimum_effort
    if expected:
        assert result.names == list(expected)


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
    """A short sweep of the cell (the benchmark `bench_population_sweep` runs the long one):
    every run ends terminal or by its task cap, and none collides or breaks separation."""
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
            "2",
            "--json",
        ]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["runs"] == 2
    assert report["completed"] + report["capped"] == 2
    assert report["collisions"] == 0
    assert report["failures"] == []
