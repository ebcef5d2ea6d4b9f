"""The closed-loop cell: every Table 2 row through the full diagram, read back from physics."""

import dataclasses

import pytest
from cell_checks import check_catalogue_run

from hrc_drake.cell.run.run import build_closed_loop, run_scenario, shared_planner
from hrc_drake.cell.scenario import LEAN, load_cell_scenario, motion_options
from hrc_drake.scenario.load import table2_scenarios
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.spec import load_spec

WAIT = "{interaction: {mode: wait}}"  # the robot waits for each indication

pytestmark = pytest.mark.slow

ROWS = table2_scenarios()


@pytest.fixture(scope="module")
def space():
    return generate_states(load_spec())


def _terminal_configurations(space):
    return {
        space.configuration(s) for s in range(space.n_states) if space.kind[s] == StateKind.TERMINAL
    }


@pytest.mark.parametrize("row", ROWS, ids=[r.name for r in ROWS])
def test_table2_row_in_the_cell(row, space):
    loop = build_closed_loop(load_cell_scenario(row.name, LEAN))
    result = loop.run()
    # Terminal in the row's states, no collision, separation kept (the operator's body shares
    # the desk, a lean row's default).
    check_catalogue_run(row.name, result)
    assert result.names == list(row.minimum_effort) and result.safety.min_separation > 0
    # Without faults nothing is injected, and the controller detects none from its measurements.
    assert result.faults == () and loop.status.detections == ()
    # The final configuration as contact shows it is a terminal one, and the one reached.
    assert result.final_tokens in _terminal_configurations(space)
    assert result.final_tokens == frozenset(result.states[-1])
    # Carried by friction alone, no part was dropped or let go off its seat on the way.
    assert not any("not in the gripper" in e or "does not sit" in e for e in result.events)
    # The operator's deviations are the scenario's; the cell shows what was really done.
    for task in result.tasks:
        assert task.indicated == row.script.get(task.step, task.proposed)
        assert task.observed == task.indicated


def test_state_comes_from_contact_not_from_the_operator(space):
    """The operator indicates F02 but the part really lands in F03: the cell state says F03."""
    # The operator indicates F02 at step 3. The misplacing planner takes no measured start, so
    # the robot waits for each indication (it never turns mid-move).
    row7 = load_cell_scenario("row7-forces-9", [LEAN, WAIT])
    motion = shared_planner(motion_options(row7))

    def misplacing_planner(configuration, task, last, layout):
        if task == "F02" and "S23" in configuration:
            plan = motion.plan_task(configuration, "F03", layout=layout)
            return dataclasses.replace(plan, task="F02")
        return motion.plan_task(configuration, task, last_token=last, layout=layout)

    result = run_scenario(row7, planner=misplacing_planner)
    assert result.error is None
    assert result.tasks[2].indicated == "F02" and result.tasks[2].observed == "F03"
    assert result.names == ["1", "2", "7", "10"]


def test_recording_is_a_self_contained_html(tmp_path):
    path = tmp_path / "row5.html"
    result = run_scenario("row5-forces-5", record=path, scenario_text=LEAN)
    assert result.done and result.recording == path
    text = path.read_text()
    assert "<html" in text.lower() and len(text) > 1_000_000
    assert [p.name for p in tmp_path.iterdir()] == ["row5.html"]


def test_the_next_plan_is_ready_when_the_operator_answers():
    """While the operator bolts, the robot plans the task it will propose next."""
    # Options no other test uses: a planning worker of its own (one per cell and options), with
    # an empty plan cache.
    fresh = load_cell_scenario("row4-forces-4", [LEAN, "{motion: {hold_time: 0.55}}"])
    ahead = run_scenario(fresh)
    # Step 1 the operator overrides F1 with F3 while the robot is on its way with F1: the
    # re-target to F3 from the lift's end was asked with the commitment; later ones while the
    # operator bolted.
    assert ahead.done and list(ahead.plan_ready) == [True, True, True]
    assert ahead.tasks[0].committed == "F1" and ahead.tasks[0].retargeted
    # Another fresh worker, without planning ahead: no plan is ready at any boundary.
    cold = load_cell_scenario(
        "row4-forces-4", [LEAN, "{run: {plan_ahead: false}, motion: {hold_time: 0.6}}"]
    )
    behind = run_scenario(cold)
    assert behind.done and list(behind.plan_ready) == [False, False, False]
    assert behind.states == ahead.states
