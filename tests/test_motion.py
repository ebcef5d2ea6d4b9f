"""Motion layer: every task of the flange graph plans and validates; poses follow the frames."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion import (
    MotionPlanner,
    Stage,
    UnreachableError,
    check_plan,
    resolve_task,
    validate_plan,
)
from hrc_drake.motion.ik import solve_ik
from hrc_drake.motion.poses import part_pose, tcp_in_part, tcp_pose
from hrc_drake.motion.scene import Layout, load_cell_frames
from hrc_drake.motion.trajectory import free_path, path_clearance
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO


def _edges():
    graph = generate_states(load_spec()).to_networkx()
    edges = []
    for u, v, data in graph.edges(data=True):
        name = f"{graph.nodes[u]['name']}->{graph.nodes[v]['name']}:{data['task']}"
        last = u[-1] if u else None
        edges.append(pytest.param(graph.nodes[u]["configuration"], data["task"], last, id=name))
    return edges


EDGES = _edges()


@pytest.fixture(scope="module")
def model_frames():
    return load_cell_frames(CellDesign.of(load_spec()))


@pytest.fixture(scope="module")
def planner(model_frames):
    return MotionPlanner(frames=model_frames)


def test_flange_graph_has_the_papers_edges():
    assert len(EDGES) == 38  # 19 assembly edges of Figure 8, each with its undo


@pytest.mark.parametrize(("configuration", "task", "last_token"), EDGES)
def test_every_task_of_the_graph_gets_a_valid_plan(planner, configuration, task, last_token):
    plan = planner.plan_task(configuration, task, last_token=last_token)
    report = validate_plan(plan, planner)
    assert report.samples >= plan.duration * 100
    assert report.min_distance >= planner.options.clearance
    assert report.max_tcp_speed <= planner.options.tcp_speed_limit


def test_plan_goes_home_grasp_carry_place_hold_release_retreat(planner):
    plan = planner.plan_task(frozenset({"F1"}), "S23")
    stages = [s.stage for s in plan.segments]
    assert stages == list(Stage)
    assert plan.segments[0].start == 0.0
    assert plan.segments[-1].end == pytest.approx(plan.duration)
    for before, after in zip(plan.segments, plan.segments[1:], strict=False):
        assert after.start == pytest.approx(before.end)
    assert plan.t_in_place == pytest.approx(plan.segment(Stage.HOLD).start)
    assert plan.t_release == pytest.approx(plan.segment(Stage.HOLD).end)
    assert plan.t_release - plan.t_in_place == pytest.approx(planner.options.hold_time)
    np.testing.assert_allclose(plan.positions(0.0), planner.q_home, atol=1e-9)
    np.testing.assert_allclose(plan.positions(plan.duration), planner.q_home, atol=1e-9)
    assert plan.trajectory.rows() == 6
    # Still while held: the operator bolts.
    np.testing.assert_allclose(
        plan.positions(plan.t_in_place), plan.positions(plan.t_release), atol=1e-9
    )


def test_gripper_opens_before_grasp_closes_on_the_part_and_opens_at_release(planner):
    plan = planner.plan_task(frozenset(), "S12")
    width = planner.frames.widths["square_flange"]
    grasp = plan.segment(Stage.GRASP)
    assert width == pytest.approx(0.090, abs=1e-6)
    assert plan.gripper_opening(grasp.start) > width
    # Closed past the part's width, so that the fingers stall on it (a grip is detected).
    assert plan.grip_width == pytest.approx(width)
    assert plan.gripper_opening(grasp.end) == pytest.approx(width - planner.options.grip_squeeze)
    closed = width - planner.options.grip_squeeze
    assert plan.gripper_opening(plan.t_in_place) == pytest.approx(closed)
    assert plan.gripper_opening(plan.t_release) == pytest.approx(closed)
    assert plan.gripper_opening(plan.segment(Stage.RELEASE).end) > width
    assert all(0.0 <= plan.gripper_opening(t) <= 0.110 for t in np.linspace(0, plan.duration, 50))


def test_the_square_flange_is_grasped_where_the_opened_pads_reach_it(planner):
    """At the end of the grasp (the fingers still open by the gap) the tcp stands 16.3 mm
    further along the approach than the square flange's `grasp` frame: where the RG2's pads,
    swung back at its 90 mm width, close on that frame (`tcp_in_part`)."""
    plan = planner.plan_task(frozenset(), "S12")
    scene = planner.scene(plan.phases[0].layout)
    model = scene.plant.GetModelInstanceByName("square_flange")
    X_part_grasp = scene.plant.GetFrameByName("grasp", model).GetFixedPoseInBodyFrame()
    X_W_grasp = planner.frames.homes["square_flange"] @ X_part_grasp
    X_tcp = scene.tcp_pose(plan.positions(plan.segment(Stage.GRASP).end))
    np.testing.assert_allclose(
        X_W_grasp.InvertAndCompose(X_tcp).translation(), [0.0, 0.0, 0.0163], atol=1e-3
    )


def test_part_is_at_its_target_when_in_place(planner):
    frames = planner.frames
    configuration = frozenset({"S12"})
    plan = planner.plan_task(configuration, "F02")
    scene = planner.scene(plan.phases[0].layout)
    X_target = tcp_pose(frames, plan.instance, part_pose(frames, "F02", {"S12", "F02"}))
    X_tcp = scene.tcp_pose(plan.positions(plan.t_in_place))
    np.testing.assert_allclose(X_tcp.translation(), X_target.translation(), atol=1e-3)
    angle = (X_tcp.rotation().inverse() @ X_target.rotation()).ToAngleAxis().angle()
    assert angle < 1e-2


def test_poses_come_from_the_seat_and_row_frames(model_frames):
    frames = model_frames
    slot = {k: frames.seats[k].translation() for k in (1, 2, 3)}
    np.testing.assert_allclose(part_pose(frames, "F3", set()).translation(), slot[3])
    square = part_pose(frames, "S23", set()).translation()
    np.testing.assert_allclose(square, (slot[2] + slot[3]) / 2)
    # F0k sits on the square's row over base slot k, wherever the square is.
    for host, k in (("S12", 1), ("S12", 2), ("S23", 2), ("S23", 3)):
        p = part_pose(frames, f"F0{k}", {host}).translation()
        np.testing.assert_allclose(p[:2], slot[k][:2], atol=1e-9)
        assert p[2] > slot[k][2]
    with pytest.raises(ValueError, match="F03"):
        part_pose(frames, "F03", {"S12"})


def test_which_instance_moves(model_frames):
    frames = model_frames
    assert resolve_task(frames, set(), "F1").instance == "oval_flange_1"
    assert resolve_task(frames, {"F1", "S23"}, "F03").instance == "oval_flange_2"
    assert resolve_task(frames, {"S12"}, "F01").instance == "oval_flange_1"
    # States 11 (F3, S12, F01) and 17 (S12, F01, F3): one configuration, the last part differs.
    move = resolve_task(frames, {"F3", "S12", "F01"}, UNDO, last_token="F01")
    assert (move.instance, move.source, move.target) == ("oval_flange_2", "F01", None)
    move = resolve_task(frames, {"F3", "S12", "F01"}, UNDO, last_token="F3")
    assert (move.instance, move.source) == ("oval_flange_2", "F3")
    assert move.after == {"S12": "square_flange", "F01": "oval_flange_1"}
    with pytest.raises(ValueError, match="last_token"):
        resolve_task(frames, {"F1"}, UNDO)


def test_a_seat_out_of_reach_names_the_task_and_the_constraint(planner):
    frames = planner.frames
    far = RigidTransform(frames.seats[1].rotation(), [1.5, 0.0, frames.seats[1].translation()[2]])
    planner = MotionPlanner(frames=frames.with_seat(1, far), q_home=planner.q_home)
    with pytest.raises(UnreachableError, match=r"task F1: the pre-place pose") as error:
        planner.plan_task(frozenset(), "F1")
    assert error.value.task == "F1"
    assert error.value.constraint == "position"


def test_a_seat_inside_the_table_fails_on_minimum_distance(planner):
    frames = planner.frames
    sunk = RigidTransform(frames.seats[2].rotation(), frames.seats[2].translation() - [0, 0, 0.05])
    planner = MotionPlanner(frames=frames.with_seat(2, sunk), q_home=planner.q_home)
    with pytest.raises(UnreachableError, match="minimum distance") as error:
        planner.plan_task(frozenset(), "F2")
    assert error.value.constraint == "minimum distance"


def test_kto_adds_distance_constraints_when_the_direct_path_collides(planner):
    # The pads 25 mm above the seats, from over slot 1 to past the square on slots 2-3: the
    # square stands in the way of any path that keeps that height.
    scene = planner.scene(Layout.of({"S23": "square_flange"}, None, 0.061))
    R = scene.tcp_pose(planner.q_home).rotation()
    seat = planner.frames.seats[1].translation()

    def posture(y):
        X = tcp_in_part(RigidTransform(R, [seat[0], y, seat[2] + 0.025]), 0.061)
        return solve_ik(
            scene,
            X,
            [planner.q_home],
            planner.q_home,
            min_distance=0.012,
            task="test",
            waypoint="end",
        )

    q0, q1 = posture(seat[1]), posture(0.15)
    assert scene.min_distance((q0 + q1) / 2)[0] < 0.0
    path, constrained = free_path(scene, q0, q1, planner.limits, planner.options)
    assert constrained
    clearance, pair = path_clearance(scene, path, 400)
    assert clearance >= planner.options.clearance, pair


def test_validation_reports_a_broken_limit(planner):
    plan = planner.plan_task(frozenset(), "F1")
    strict = dataclasses.replace(planner.options, tcp_speed_limit=0.1)

    class Slower:
        options = strict
        limits = planner.limits
        scene = staticmethod(planner.scene)

    report = check_plan(plan, Slower())
    assert not report.ok
    assert any("tcp speed" in p for p in report.problems)


def test_same_seed_same_plan(planner):
    again = MotionPlanner(frames=planner.frames)
    a = planner.plan_task(frozenset(), "F3")
    b = again.plan_task(frozenset(), "F3")
    assert a.duration == b.duration
    np.testing.assert_array_equal(a.positions(1.0), b.positions(1.0))
