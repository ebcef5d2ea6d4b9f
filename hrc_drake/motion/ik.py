"""Inverse kinematics of the tcp with SNOPT, and the error raised when a pose is out of reach."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver

from hrc_drake.motion.scene import PlanningScene

POSITION_TOLERANCE = 5e-4
ORIENTATION_TOLERANCE = 5e-3


class UnreachableError(RuntimeError):
    """No joint posture reaches a pose a task needs.

    Attributes:
        task: the task token.
        waypoint: which pose (e.g. "pre-place", "place").
        constraint: the constraint that cannot be met: "position", "orientation" or
            "minimum distance".
    """

    def __init__(self, task: str, waypoint: str, constraint: str, detail: str):
        self.task = task
        self.waypoint = waypoint
        self.constraint = constraint
        super().__init__(
            f"task {task}: the {waypoint} pose is unreachable — {constraint} constraint "
            f"violated ({detail})"
        )


def _solve(
    scene: PlanningScene,
    X_W_tcp: RigidTransform,
    seeds: Sequence[np.ndarray],
    q_nominal: np.ndarray,
    *,
    orientation: bool,
    min_distance: float | None,
) -> np.ndarray | None:
    plant = scene.plant
    ik = InverseKinematics(plant, scene.plant_context, with_joint_limits=True)
    p = X_W_tcp.translation()
    ik.AddPositionConstraint(
        scene.tcp_frame,
        np.zeros(3),
        plant.world_frame(),
        p - POSITION_TOLERANCE,
        p + POSITION_TOLERANCE,
    )
    if orientation:
        ik.AddOrientationConstraint(
            plant.world_frame(),
            X_W_tcp.rotation(),
            scene.tcp_frame,
            RigidTransform().rotation(),
            ORIENTATION_TOLERANCE,
        )
    if min_distance is not None:
        ik.AddMinimumDistanceLowerBoundConstraint(min_distance, 0.02)
    q = ik.q()
    prog = ik.get_mutable_prog()
    prog.AddQuadraticErrorCost(np.eye(len(q_nominal)), q_nominal, q)
    solver = SnoptSolver()
    # A failing seed should fail fast: a feasible IK converges in a few dozen iterations.
    prog.SetSolverOption(solver.solver_id(), "Major iterations limit", 200)
    for seed in seeds:
        result = solver.Solve(prog, np.asarray(seed, dtype=float))
        if result.is_success():
            return result.GetSolution(q)
    return None


# How far each joint of a seed is moved for its second chance [rad].
_NUDGE = 1e-3


def _second_chance(
    scene: PlanningScene,
    X_W_tcp: RigidTransform,
    seeds: Sequence[np.ndarray],
    q_nominal: np.ndarray,
    min_distance: float,
) -> np.ndarray | None:
    """A clear posture from each seed alone, then from each seed nudged by `_NUDGE`, without the
    distance constraint and then with it; None if none. Where the seeds together found nothing
    clear, SNOPT may still from one of them: it stalls from a seed whose tcp turns exactly the
    orientation tolerance off (the straight way down from a pre-place that the IK left there:
    the constraint's gradient vanishes), and with the distance constraint it can fail from a
    seed whose plain answer is already clear (a UR3 putting a part back in the tray from
    slot 4 of a 4-slot cell at a 75 mm pitch: 16.9 mm clear, the constrained solve failed)."""
    for seed in [*seeds, *(np.asarray(s, dtype=float) + _NUDGE for s in seeds)]:
        q = _solve(scene, X_W_tcp, [seed], q_nominal, orientation=True, min_distance=None)
        if q is None:
            continue
        if scene.min_distance(q)[0] >= min_distance:
            return q
        q = _solve(scene, X_W_tcp, [q], q_nominal, orientation=True, min_distance=min_distance)
        if q is not None:
            return q
    return None


def solve_ik(
    scene: PlanningScene,
    X_W_tcp: RigidTransform,
    seeds: Sequence[np.ndarray],
    q_nominal: np.ndarray,
    *,
    min_distance: float,
    task: str,
    waypoint: str,
) -> np.ndarray:
    """A posture putting the tcp at X_W_tcp, clear of collisions, near `q_nominal`.

    Tries each seed in turn with SNOPT. Where that finds nothing clear, each seed alone and
    nudged (`_second_chance`) before the pose is called unreachable. Raises UnreachableError
    naming the violated constraint, found by re-solving without the distance constraint, then
    without orientation.
    """
    # Solving without the distance constraint first is fast, and its answer is usually clear.
    q_free = _solve(scene, X_W_tcp, seeds, q_nominal, orientation=True, min_distance=None)
    where = np.array2string(X_W_tcp.translation(), precision=3)
    if q_free is not None:
        if scene.min_distance(q_free)[0] >= min_distance:
            return q_free
        q = _solve(
            scene,
            X_W_tcp,
            [q_free, *seeds],
            q_nominal,
            orientation=True,
            min_distance=min_distance,
        )
        if q is not None:
            return q
    q = _second_chance(scene, X_W_tcp, seeds, q_nominal, min_distance)
    if q is not None:
        return q
    if q_free is not None:
        detail = f"the arm reaches tcp at {where} only by coming closer than {min_distance} m"
        raise UnreachableError(task, waypoint, "minimum distance", detail)
    if _solve(scene, X_W_tcp, seeds, q_nominal, orientation=False, min_distance=None) is not None:
        raise UnreachableError(
            task, waypoint, "orientation", f"tcp at {where} cannot take the grasp orientation"
        )
    raise UnreachableError(task, waypoint, "position", f"tcp at {where} is out of reach")
