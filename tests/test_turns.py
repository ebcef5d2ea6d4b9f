"""Where along a committed plan the robot turns to the task the operator indicates, and how
(`hrc_drake.cell.controller.anticipation`): on plans of the flange case, no simulation."""

import numpy as np
import pytest

from hrc_drake.cell.controller.anticipation import (
    Turn,
    back_above,
    lift_end,
    turn_at,
    turn_point,
    wait_point,
)
from hrc_drake.motion.plan import Stage
from hrc_drake.tasks.tokens import UNDO


@pytest.fixture(scope="module")
def planner():
    from hrc_drake.motion.planner import MotionPlanner

    return MotionPlanner()


@pytest.fixture(scope="module")
def f1(planner, flange_space):
    """The plan of F1 from the empty base: the robot's commitment in the tests below."""
    return planner.plan_task(flange_space.configuration(0), "F1")


def _speed(plan, tau: float) -> float:
    return float(np.abs(plan.trajectory.EvalDerivative(tau, 1)).max())


def test_rest_points_are_where_the_plans_motions_meet(f1):
    grasp = f1.segment(Stage.GRASP).start
    assert grasp < lift_end(f1) < wait_point(f1) < f1.t_in_place
    # The arm is still there: a turn onto a plan that starts at rest keeps its speed continuous.
    assert _speed(f1, lift_end(f1)) < 1e-6 and _speed(f1, wait_point(f1)) < 1e-6
    assert _speed(f1, (lift_end(f1) + wait_point(f1)) / 2) > 0.05  # carrying in between


def test_a_retarget_turns_at_the_next_rest_point(f1, flange_space):
    spec = flange_space.spec
    end, place = lift_end(f1), wait_point(f1)
    # The same kind of part on another seat: a re-target wherever the part is not yet placing,
    # before the grasp as well (the robot picks it and goes on).
    for tau in (0.0, f1.segment(Stage.GRASP).start, end, (end + place) / 2, place):
        assert turn_at(f1, tau, spec, "F3") == Turn.RETARGET, tau
    assert turn_at(f1, place + 0.01, spec, "F3") == Turn.TOO_LATE
    assert turn_point(f1, 0.0) == turn_point(f1, end) == end
    assert turn_point(f1, end + 0.01) == turn_point(f1, place) == place


def test_a_swap_turns_by_where_the_part_is(f1, flange_space):
    spec = flange_space.spec
    grasp, end, place = f1.segment(Stage.GRASP).start, lift_end(f1), wait_point(f1)
    assert turn_at(f1, grasp - 0.01, spec, "S12") == Turn.REPLAN  # nothing in the fingers
    assert turn_at(f1, (grasp + end) / 2, spec, "S12") == Turn.LATER  # closing or lifting
    assert turn_at(f1, (end + place) / 2, spec, "S12") == Turn.RETURN  # carrying
    assert turn_at(f1, place, spec, "S12") == Turn.RETURN  # waiting above the seat
    assert turn_at(f1, place + 0.01, spec, "S12") == Turn.TOO_LATE
    # A plan turned to its own task (an obstacle appeared) is re-planned by the same rules.
    assert turn_at(f1, (end + place) / 2, spec, "F1") == Turn.RETURN


def test_a_part_put_back_is_left_from_above_it(planner, f1, flange_space):
    # The swap's return: the part carried from the lift's end back to its tray home; the robot
    # goes on to the indicated task from above the part, before the plan's leg home.
    q = f1.trajectory.value(lift_end(f1)).ravel()
    back = planner.plan_task(
        flange_space.configuration(0), UNDO, instance=f1.instance, q_start=q, held=True
    )
    above = back_above(back)
    assert back.segment(Stage.RELEASE).end <= above < back.duration
    assert _speed(back, above) < 1e-6
    assert back.gripper_opening(above) > back.grip_width  # let go


def test_a_turn_before_the_grasp_keeps_the_fingers_open_until_clear_of_the_part(
    planner, flange_space
):
    """Turned to another part on the way down to the square flange (the fingers open around
    it), the plan from there keeps the square's opening until the arm is clear of the cell and
    only then closes to the oval flange's: closing at once closed the fingers on the square
    (`stochastic-long` stopped there, the arm pushed)."""
    square = planner.plan_task(flange_space.configuration(0), "S23")
    tau = square.segment(Stage.GRASP).start - 0.05  # going down, the fingers by the square
    q = square.trajectory.value(tau).ravel()
    wide = square.gripper_opening(tau)
    turned = planner.plan_task(flange_space.configuration(0), "F1", q_start=q, start_opening=wide)
    oval = turned.gripper_opening(turned.segment(Stage.GRASP).start)
    assert wide > oval + 0.03
    clear = next(m for m in turned.motions if m.name == "up, clear of the cell")
    for t in np.linspace(0.0, clear.start + clear.duration, 8):
        assert turned.gripper_opening(t) == pytest.approx(wide)
    # Narrowed on the way to the pre-grasp, before going down to the oval flange.
    down = next(m for m in turned.motions if m.name == "down to grasp")
    assert turned.gripper_opening(down.start) == pytest.approx(oval)


def test_a_swap_turned_just_past_the_lifts_end_is_planned_back_to_the_tray(planner, f1):
    """Turned just past the lift's end, the way back to the tray starts almost at the pre-place
    above it: a move of 0.011 rad, on which KTO ran out of iterations (where the arm stopped in
    run 11 of exact vs habitual in the population sweep); it is the straight line."""
    stopped = np.array([-1.125532, -1.272209, 1.284885, -1.585087, -1.567562, 2.012624])
    assert 0.0 < np.abs(stopped - f1.trajectory.value(lift_end(f1)).ravel()).max() < 0.05
    back = planner.plan_task(frozenset(), UNDO, instance=f1.instance, q_start=stopped, held=True)
    assert back.task == UNDO and back.carrying(0.0) == f1.instance
    assert back.trajectory.value(0.0).ravel() == pytest.approx(stopped, abs=1e-4)
    assert back.trajectory.value(back.duration).ravel() == pytest.approx(planner.q_home, abs=1e-6)


def test_a_carry_back_toppra_cannot_time_is_timed_on_a_refit_of_its_path(planner):
    """Where the arm stopped carrying F01's flange in run 15 of mpc vs change-of-mind (the
    population sweep), the way back to the tray is a KTO path Toppra fails on at any grid; the
    cubic through samples of it is timed instead, and the part goes back."""
    stopped = np.array([-0.953173, -1.391857, 1.393899, -1.573851, -1.567462, 2.184938])
    back = planner.plan_task(
        frozenset({"S12"}),
        UNDO,
        last_token="S12",
        layout={"square_flange": "S12"},
        instance="oval_flange_1",
        q_start=stopped,
        held=True,
    )
    assert back.carrying(0.0) == "oval_flange_1"
    assert back.trajectory.value(0.0).ravel() == pytest.approx(stopped, abs=1e-4)
    assert back.trajectory.value(back.duration).ravel() == pytest.approx(planner.q_home, abs=1e-6)


def test_another_part_indicated_as_the_arm_reaches_the_pre_place_pose_stops_it_there(f1):
    """An indication of another part (here `undo`) taken an update before the arm reaches the
    pre-place pose: the arm stops at that pose, where it is at rest, and turns from there. It
    used to slow down along its path, which took it on down to the seat: too late to turn, the
    run stopped (random operator, population sweep)."""
    from dataclasses import replace

    from hrc_drake.cell.controller.supervisor_state import (
        Mode,
        PlanClock,
        SupervisorStatus,
        TurnState,
    )
    from hrc_drake.cell.run.run import build_closed_loop
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    supervisor = build_closed_loop(load_cell_scenario("row1-optimal", LEAN)).controller.supervisor
    above = wait_point(f1)
    committed = TurnState(committed="F1")
    moving = SupervisorStatus(
        mode=Mode.EXECUTE, clock=PlanClock(plan=f1, tau=above - 0.01, tau_time=10.0), turn=committed
    )
    held = f1.grip_width  # the fingers on the part carried (they let go only after the seat)
    turning = supervisor._follower.advance(
        replace(moving, turn=replace(committed, change=UNDO)), 1.0, 10.02, held
    )
    assert turning.clock.tau == pytest.approx(above) and turning.clock.speed == 0.0
    assert turning.plan_time(10.1) == pytest.approx(above)
    assert turn_at(f1, turning.plan_time(10.02), supervisor._space.spec, UNDO) == Turn.RETURN
    # Still waiting for the indication: it waits there at speed; with none to wait for and no
    # turn, it goes on down to the seat.
    awaiting = replace(moving, turn=replace(committed, awaiting=True))
    waiting = supervisor._follower.advance(awaiting, 1.0, 10.02, held)
    assert waiting.clock.tau == pytest.approx(above) and waiting.clock.speed == 1.0
    placing = supervisor._follower.advance(moving, 1.0, 10.02, held)
    assert placing.plan_time(10.02) > above
