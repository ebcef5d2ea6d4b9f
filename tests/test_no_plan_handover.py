"""A task the robot cannot plan mid-run is handed to the operator and the assembly goes on to its
terminal state (issue 50, item 4): the planner is told to fail two tasks, as an unreachable seat
would make it (the cause is injected: the run must not depend on a layout the reach check lets
through)."""

import pytest

from hrc_drake.cell.run.run import run_scenario, shared_planner
from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario, motion_options
from hrc_drake.motion import UnreachableError
from hrc_drake.motion.service import planner_function
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

# Step 1 the robot starts on its proposal F1 and the operator indicates F3 three seconds later,
# when the part is lifted: the re-target's plan fails (so does F3 from the tray), the part goes
# back and F3 is handed over. Step 2 the robot commits to S12, finds no plan, waits for the
# indication, and hands S12 over. Step 3 (F01) is the robot's. A short handover keeps it lean.
SCENARIO = (
    "{operator: {deviations: [{step: 1, task: F3}]}, "
    "interaction: {mode: anticipate, delay: {distribution: fixed, median: 3.0}}, "
    "run: {handover_time: 1.0}}"
)
NO_PLAN = {("F3", frozenset()), ("S12", frozenset({"F3"}))}


@pytest.mark.slow
def test_a_task_the_robot_cannot_plan_is_handed_over_and_the_run_ends_terminal():
    scenario = load_cell_scenario("row1-optimal", [LEAN, SCENARIO])
    motion = shared_planner(motion_options(scenario), cell_design(scenario, load_spec()))
    plan = planner_function(motion)
    asked: list[tuple[str, bool]] = []

    def planner(configuration, task, last_token, layout, **measured):
        asked.append((task, bool(measured.get("held"))))
        if (task, frozenset(configuration)) in NO_PLAN:
            raise UnreachableError(task, "place", "position", "injected for this test")
        return plan(configuration, task, last_token, layout, **measured)

    result = run_scenario(scenario, planner=planner, motion_planner=motion)
    report = result.to_json()
    assert report["error"] is None and report["terminal"], report["error"]
    assert report["states"] == [[], ["F3"], ["F3", "S12"], ["F3", "S12", "F01"]]
    assert report["collisions"] == 0
    first, second, third = report["steps"]
    # Carrying F1's part, the re-target to F3 failed: the part went back to its tray (a held
    # undo), F3 from there failed too, and the operator did F3 by hand.
    assert ("F3", True) in asked and (UNDO, True) in asked
    assert first["committed"] == "F1" and first["operator"] == "F3"
    assert first["handed_over"] and "no plan for F3" in first["handover_reason"]
    assert "injected for this test" in first["handover_reason"]
    # The robot could not start on its commitment S12: it waited, then handed S12 over.
    assert second["committed"] is None and second["observed"] == "S12"
    assert second["handed_over"] and "no plan for S12" in second["handover_reason"]
    assert not third["handed_over"] and third["observed"] == "F01"
    assert report["handovers"] == 2
