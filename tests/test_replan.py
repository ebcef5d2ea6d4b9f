"""Re-planning from the measured world: a part picked where it lies (after a drop, or a part that
did not seat) and a plan starting from the arm's measured posture, in process and through the
plan service's worker (issue 17: grip-lost and no-seat recoveries)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from hrc_drake.cell_models import TABLE, CellDesign
from hrc_drake.motion import (
    MotionOptions,
    MotionPlanner,
    Plan,
    PlanningError,
    Stage,
    UnreachableError,
    validate_plan,
)
from hrc_drake.motion.ik import ORIENTATION_TOLERANCE
from hrc_drake.motion.plan_io import plan_to_data
from hrc_drake.motion.plan_request import PlanFailure, PlanRequest
from hrc_drake.motion.poses import part_pose, pose_from_values, pose_values, tcp_pose
from hrc_drake.motion.service import (
    InlinePlanService,
    planner_function,
    shared_plan_service,
)
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

PART = "oval_flange_1"


@pytest.fixture(scope="module")
def planner():
    return MotionPlanner()


@pytest.fixture(scope="module")
def on_the_table(planner) -> RigidTransform:
    """Where oval_flange_1 lies after a drop: flat on the table beside the tray's end nearest
    the plate (the tray spans x 0.055-0.345 m; its home is at x 0.26, y -0.29), 8 cm toward the
    plate in y, yawed 0.7 rad from its home; resting on its boss (4.5 mm below its frame)."""
    home = planner.frames.homes[PART]
    R = home.rotation() @ RotationMatrix.MakeZRotation(0.7)
    return RigidTransform(R, [0.39, home.translation()[1] + 0.08, 0.0045])


@pytest.fixture(scope="module")
def mid_carry(planner) -> np.ndarray:
    """Where the arm is when a grasp is lost: halfway through the carry of an ordinary F1."""
    normal = planner.plan_task(frozenset(), "F1")
    carry = next(m for m in normal.motions if m.name == "carry to pre-place")
    return normal.positions(carry.start + 0.5 * carry.duration)


def _tcp(planner: MotionPlanner, plan: Plan, t: float) -> RigidTransform:
    return planner.scene(plan.phases[0].layout).tcp_pose(plan.positions(t))


def _assert_near(X: RigidTransform, Y: RigidTransform) -> None:
    """Within 1 mm, and the IK's orientation tolerance."""
    assert np.linalg.norm(X.translation() - Y.translation()) < 1e-3
    angle = X.rotation().InvertAndCompose(Y.rotation()).ToAngleAxis().angle()
    assert angle < ORIENTATION_TOLERANCE + 1e-6


def test_a_dropped_part_is_picked_where_it_lies_and_placed_at_its_seat(planner, on_the_table):
    plan = planner.plan_task(frozenset(), "F1", instance=PART, source_pose=on_the_table)
    assert (plan.task, plan.instance) == ("F1", PART)
    # The grasp is the part's grasp frame where it lies (not in its tray home).
    grasped = _tcp(planner, plan, plan.segment(Stage.GRASP).end)
    _assert_near(grasped, tcp_pose(planner.frames, PART, on_the_table))
    # The pick scene has the part there, and the gripper may touch what it lies on.
    pick = plan.phases[0].layout
    assert [instance for instance, _ in pick.loose] == [PART]
    assert ("rg2", TABLE) in plan.phases[1].allowed_contacts
    validate_plan(plan, planner)
    # A part lying half a turn about its grasp axis from there (the same, for a symmetric
    # part) is grasped the same: the grasp nearest the home grasp, not the wrist wound by π.
    turned = on_the_table @ RigidTransform(RotationMatrix.MakeZRotation(np.pi))
    again = planner.plan_task(frozenset(), "F1", instance=PART, source_pose=turned)
    _assert_near(_tcp(planner, again, again.segment(Stage.GRASP).end), grasped)
    # Placed where the ordinary F1 places it.
    normal = planner.plan_task(frozenset(), "F1")
    placed = _tcp(planner, plan, plan.t_in_place)
    _assert_near(placed, _tcp(planner, normal, normal.t_in_place))
    _assert_near(placed, tcp_pose(planner.frames, PART, part_pose(planner.frames, "F1", {"F1"})))


def test_a_part_lying_on_another_may_be_touched_while_grasped(planner):
    # oval_flange_1 fell on the square flange in its tray home (on the square's rims).
    square = planner.frames.homes["square_flange"]
    on_square = RigidTransform(
        square.rotation() @ RotationMatrix.MakeZRotation(0.3),
        square.translation() + np.array([0.0, 0.0, 0.0205]),
    )
    plan = planner.plan_task(frozenset(), "F1", instance=PART, source_pose=on_square)
    assert ("rg2", "square_flange") in plan.phases[1].allowed_contacts
    assert (PART, "square_flange") in plan.phases[3].allowed_contacts  # the lift
    assert ("rg2", "oval_flange_2") not in plan.phases[1].allowed_contacts
    validate_plan(plan, planner)


def test_a_plan_from_a_measured_posture_starts_there_and_ends_home(
    planner, on_the_table, mid_carry
):
    plan = planner.plan_task(
        frozenset(), "F1", instance=PART, source_pose=on_the_table, q_start=mid_carry
    )
    # The planner plans from the posture rounded to 1e-4 rad (the plan cache's resolution).
    np.testing.assert_allclose(plan.positions(0.0), mid_carry, rtol=0, atol=5e-5 + 1e-12)
    np.testing.assert_allclose(plan.positions(plan.duration), planner.q_home, rtol=0, atol=1e-9)
    assert plan.motions[0].name == "start to pre-grasp"
    validate_plan(plan, planner)


def test_what_cannot_be_replanned_is_refused_with_the_reason(planner, on_the_table):
    tilted = RigidTransform(
        on_the_table.rotation() @ RotationMatrix.MakeXRotation(0.7),
        on_the_table.translation() + np.array([0.0, 0.0, 0.015]),
    )
    with pytest.raises(UnreachableError, match=rf"{PART} lies tilted 0\.70 rad from upright"):
        planner.plan_task(frozenset(), "F1", instance=PART, source_pose=tilted)
    # A start posture past a joint's limits.
    past = planner.q_home.copy()
    past[4] = 7.0
    with pytest.raises(PlanningError, match=r"past joint 5's limits"):
        planner.plan_task(frozenset(), "F1", q_start=past)
    with pytest.raises(ValueError, match="undo"):
        planner.plan_task({"F1"}, UNDO, last_token="F1", instance=PART, source_pose=on_the_table)
    # The part to pick where it lies is not seated.
    with pytest.raises(
        ValueError, match="oval_flange_1 is not a free part, the layout has it at F1"
    ):
        planner.plan_task(
            {"F1"}, "F02", layout={PART: "F1"}, instance=PART, source_pose=on_the_table
        )


def test_the_worker_plans_a_measured_request_as_the_planner_does(planner, on_the_table, mid_carry):
    service = shared_plan_service(MotionOptions(), CellDesign.of(load_spec()))
    request = PlanRequest.of(
        frozenset(), "F1", instance=PART, source_pose=pose_values(on_the_table), start=mid_carry
    )
    tilted = PlanRequest.of(
        frozenset(),
        "F1",
        instance=PART,
        source_pose=on_the_table @ RigidTransform(RotationMatrix.MakeXRotation(0.7)),
    )
    service.request(request)
    service.request(tilted)
    mine = planner.plan_task(
        frozenset(), "F1", instance=PART, source_pose=on_the_table, q_start=mid_carry
    )
    result = service.wait(request, timeout=120.0)
    assert isinstance(result, Plan), result
    assert plan_to_data(result) == plan_to_data(mine)  # the same plan, to the bit
    failure = service.wait(tilted, timeout=120.0)
    assert isinstance(failure, PlanFailure) and failure.kind == "UnreachableError"
    assert "tilted 0.70 rad" in failure.reason
    # A pose measured 20 µm off is the same request, cached; one 1 mm off is not.
    for dx, cached in ((2e-5, True), (1e-3, False)):
        moved = RigidTransform(
            on_the_table.rotation(), on_the_table.translation() + np.array([dx, 0.0, 0.0])
        )
        near = PlanRequest.of(frozenset(), "F1", instance=PART, source_pose=moved, start=mid_carry)
        assert service.is_cached(near) is cached
    # In process, the inline service hands the planner the same arguments.
    assert InlinePlanService(planner_function(planner)).wait(request) is mine


def test_an_ordinary_request_plans_and_caches_as_before(planner, on_the_table):
    request = PlanRequest.of(frozenset(), "F1")
    assert request.key() == (frozenset(), "F1", None, None)
    assert request.keywords() == {}
    normal = planner.plan_task(frozenset(), "F1")
    assert planner.plan_task(frozenset(), "F1", instance=None, source_pose=None) is normal
    measured = planner.plan_task(frozenset(), "F1", instance=PART, source_pose=on_the_table)
    assert measured is not normal and planner.plan_task(frozenset(), "F1") is normal
    assert PlanRequest.of(frozenset(), "F1", instance=PART).key() != request.key()

    # A plan function of the four positional arguments still serves ordinary requests.
    def ordinary(configuration, task, last_token, layout):
        return planner.plan_task(configuration, task, last_token=last_token, layout=layout)

    assert InlinePlanService(ordinary).wait(request) is normal
    with pytest.raises(ValueError, match=r"a source pose needs the part lying there"):
        PlanRequest.of(frozenset(), "F1", source_pose=pose_values(on_the_table))
    with pytest.raises(ValueError, match=r"6 finite numbers"):
        PlanRequest.of(frozenset(), "F1", start=[0.0, 1.0])


def test_a_start_by_a_placed_part_first_moves_the_tool_straight_up(planner):
    # Where the arm stopped holding F1 in its seat: the fingers, closed on it, by the part and
    # the plate, closer than the planner's clearance. The next plan lifts the tool clear before
    # anything else (the fingers keep their opening until then: opened for the square flange,
    # the RG2's pads would stand 30 mm higher).
    f1 = planner.plan_task(frozenset(), "F1")
    by_the_plate, closed = f1.positions(f1.t_in_place), f1.gripper_opening(f1.t_in_place)
    plan = planner.plan_task(
        {"F1"}, "S23", layout={"oval_flange_1": "F1"}, q_start=by_the_plate, start_opening=closed
    )
    assert plan.motions[0].name == "up, clear of the cell"
    np.testing.assert_allclose(plan.positions(0.0), by_the_plate, rtol=0, atol=5e-5 + 1e-12)
    validate_plan(plan, planner)


def test_a_start_clear_with_the_fingers_wide_but_not_narrower_first_moves_straight_up(planner):
    # Where the arm was going down to the square flange in the tray, its fingers open 106 mm
    # for it, when the operator said undo (stochastic-long, step 2): clear of the flange with
    # the fingers that wide, but the undo's pick opens them to 61 mm for F1, and narrower the
    # RG2's pads stand lower, into the flange. The plan lifts the tool clear first, the fingers
    # keeping their opening, and only then moves them.
    s23 = planner.plan_task({"F1"}, "S23", layout={"oval_flange_1": "F1"})
    down = next(m for m in s23.motions if m.name == "down to grasp")
    t = down.start + 0.26
    q, wide = s23.positions(t), s23.gripper_opening(t)
    need = planner.options.clearance + planner.options.clearance_margin
    layout = s23.phases[0].layout
    assert planner.scene(replace(layout, opening=wide)).min_distance(q)[0] >= need
    assert planner.scene(replace(layout, opening=0.061)).min_distance(q)[0] < need
    plan = planner.plan_task({"F1"}, UNDO, last_token="F1", q_start=q, start_opening=wide)
    up = plan.motions[0]
    assert up.name == "up, clear of the cell"
    for tau in np.linspace(0.0, up.duration, 5):
        assert plan.gripper_opening(tau) == pytest.approx(wide)
    validate_plan(plan, planner)


def test_a_part_lying_askew_on_the_tray_is_refused_when_a_finger_would_touch_the_tray(planner):
    # Where a square flange came to rest on the tray's edge after a lost grip (measured in a
    # faulted run, row 1 with !GripLost {task: 2}): closing on it, the right finger would touch
    # the tray (the RG2's pads come down 13 mm as they close on its 90 mm). The planner says so
    # instead of planning a grasp the cell would see as a collision.
    lying = pose_from_values(
        (0.232473, -0.175711, 0.022043, 0.771955, -0.104027, -0.060447, 0.624188)
    )
    with pytest.raises(UnreachableError, match=r"closing on it, would touch the cell"):
        planner.plan_task({"F1"}, "S23", instance="square_flange", source_pose=lying, q_start=None)
    # The same part lying flat on the table beside the tray, on its bosses, is planned.
    home = planner.frames.homes["square_flange"]
    flat = RigidTransform(home.rotation(), [0.46, home.translation()[1] + 0.08, 0.0045])
    assert planner.plan_task({"F1"}, "S23", instance="square_flange", source_pose=flat)


def test_fingers_that_would_sweep_into_a_neighbour_as_they_close_are_refused(planner):
    # Where a square flange came to rest flat in the tray beside oval_flange_2 after a lost
    # grip (the fault benchmark's flange seed 1, !GripLost {task: 2, after: 0.81}): the left
    # finger goes down 5 mm clear of the oval flange and ends 2.3 mm clear of it closed on the
    # square one, but on the way the RG2's pad comes down its arc onto the oval flange's top
    # (in the cell it tipped the flange over, counted a collision). The planner says so.
    lying = RigidTransform(RollPitchYaw(0.0, 0.0, 1.671), [0.171, -0.2034, 0.0165])
    with pytest.raises(UnreachableError, match=r"left_finger vs oval_flange_2"):
        planner.plan_task({"F1"}, "S23", instance="square_flange", source_pose=lying)
    # Lying as far from its home the other way, clear of the oval flanges, it is planned.
    home = planner.frames.homes["square_flange"].translation()
    away = RigidTransform(RollPitchYaw(0.0, 0.0, 1.671), home + np.array([-0.041, 0.0, 0.0]))
    assert planner.plan_task({"F1"}, "S23", instance="square_flange", source_pose=away)


@pytest.mark.parametrize(("task", "home"), [("F3", False), (UNDO, True)])
def test_a_held_part_is_carried_from_where_the_arm_is_to_another_seat_or_home(
    planner, mid_carry, task, home
):
    # The robot started on F1 and is halfway through the carry when the operator indicates F3
    # (a re-target), or another part (a swap: the flange goes back to its tray home).
    plan = planner.plan_task(frozenset(), task, instance=PART, q_start=mid_carry, held=True)
    assert (plan.task, plan.instance) == (task, PART)
    # From where the arm is (to the plan cache's 1e-4 rad), with no pick: it starts holding
    # the part (the fingers at the grip) and goes straight on.
    np.testing.assert_allclose(plan.positions(0.0), mid_carry, atol=1e-4)
    assert plan.segment(Stage.GRASP).end == 0.0 and plan.segment(Stage.CARRY).start == 0.0
    assert plan.gripper_opening(0.0) < planner.frames.widths[PART]
    assert plan.motions[0].name == "carry to pre-place"
    X_dst = (
        planner.frames.homes[PART] if home else part_pose(planner.frames, "F3", frozenset({"F3"}))
    )
    _assert_near(_tcp(planner, plan, plan.t_in_place), tcp_pose(planner.frames, PART, X_dst))
    np.testing.assert_allclose(plan.positions(plan.duration), planner.q_home, atol=1e-6)
    validate_plan(plan, planner)
    again = planner.plan_task(frozenset(), task, instance=PART, q_start=mid_carry, held=True)
    assert again is plan  # from the plan cache
    # A held part is held somewhere: the plan needs the arm's posture.
    with pytest.raises(ValueError, match="needs its instance and q_start"):
        planner.plan_task(frozenset(), task, instance=PART, held=True)
