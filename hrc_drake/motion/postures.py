"""The UR3's reference postures: the ready family (elbow up, tool pointing down) turned toward a
point, which seeds and pulls the IK; home, above the work; and a measured start posture, checked
and lifted clear of the cell before a plan leaves it.

Apart from the planner because these are the arm's own postures, the same whatever the task:
the planner and the reach check (`hrc_drake.motion.reach_check`) both aim from them.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from hrc_drake.cell_models import TABLE
from hrc_drake.motion.ik import solve_ik
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.poses import CellFrames, tcp_pose
from hrc_drake.motion.scene import GRIPPER, PLATE, TRAY, PlanningScene
from hrc_drake.motion.trajectory import JointLimits, PlanningError, straight_waypoints

# The UR3 "ready" posture family (ROS joint conventions): elbow up, tool pointing down.
READY = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
# Where home puts the tcp: above the work, between plate and tray [m above the seats].
_HOME_HEIGHT = 0.20


def toward(scene: PlanningScene, p_W: np.ndarray) -> np.ndarray:
    """The ready posture with the shoulder pan turned toward a point."""
    p0 = scene.tcp_pose(READY).translation()
    q = READY.copy()
    q[0] = np.arctan2(p_W[1], p_W[0]) - np.arctan2(p0[1], p0[0])
    return q


def _down_rotation(frames: CellFrames) -> RotationMatrix:
    """The tcp's orientation grasping a part upright in its tray home: pointing down."""
    instance = next(iter(frames.grasps))
    return tcp_pose(frames, instance, frames.homes[instance]).rotation()


def home_posture(frames: CellFrames, scene: PlanningScene) -> np.ndarray:
    """Home: the tcp pointing down `_HOME_HEIGHT` above the seats, halfway between the plate
    and the tray. UnreachableError when the UR3 cannot reach it."""
    seats = np.array([X.translation() for X in frames.seats.values()])
    homes = np.array([X.translation() for X in frames.homes.values()])
    p = 0.5 * (seats.mean(axis=0) + homes.mean(axis=0))
    p[2] = float(np.max(seats[:, 2])) + _HOME_HEIGHT
    nominal = toward(scene, p)
    X = RigidTransform(_down_rotation(frames), p)
    return solve_ik(scene, X, [nominal], nominal, min_distance=0.012, task="home", waypoint="home")


def clear_start(
    scene: PlanningScene,
    q: np.ndarray,
    options: MotionOptions,
    frames: CellFrames,
    task: str,
    then: PlanningScene | None = None,
):
    """(postures, allowed contacts) moving the tcp straight up by the approach distance, in
    `scene` (the fingers at their start opening, which they keep on the way up), from a start
    posture closer to the cell than the optimisers' margin (the arm stopped with its fingers by
    a part or a surface), or (None, ()) when the start is clear. `then`: the scene the plan goes
    on in, the fingers at the pick's opening; a start too close in it is lifted clear too,
    since the fingers move to that opening as the arm leaves (the RG2's pads come down as they
    close: fingers clear of a part when open wide can touch it narrower)."""
    need = options.clearance + options.clearance_margin
    if all(s.min_distance(q)[0] >= need for s in (scene, then) if s is not None):
        return None, ()
    X = scene.tcp_pose(q)
    up_by = np.array([0.0, 0.0, options.approach_distance])
    X_up = RigidTransform(X.rotation(), X.translation() + up_by)
    near = tuple((GRIPPER, other) for other in (PLATE, TRAY, TABLE, *frames.design.instance_names))
    scene.set_allowed_contacts(near)
    up = straight_waypoints(scene, q, X_up, options, task=task, waypoint="clear of the cell")
    scene.set_allowed_contacts(())
    return up, near


def check_start(
    scene: PlanningScene, q: np.ndarray, limits: JointLimits, options: MotionOptions, task: str
) -> None:
    """A start posture other than home must be within the joint limits and clear of the
    cell by the optimisers' margin: the free path's collision constraints hold at its start
    too. PlanningError otherwise."""
    outside = np.flatnonzero((q < limits.lower) | (q > limits.upper))
    if outside.size:
        raise PlanningError(
            f"task {task}: the start posture {np.round(q, 4).tolist()} is past joint "
            f"{int(outside[0]) + 1}'s limits; start from a posture within them"
        )
    need = options.clearance + options.clearance_margin
    distance, pair = scene.min_distance(q)
    if distance < need:
        raise PlanningError(
            f"task {task}: the start posture is {distance * 1000:.1f} mm from {pair}; a "
            f"plan starts {need * 1000:.0f} mm clear at least: move the arm clear first"
        )
