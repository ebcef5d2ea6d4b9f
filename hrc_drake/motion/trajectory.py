"""Joint-space paths (KTO through free space, IK along straight lines) and their retiming."""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import BsplineBasis, KnotVectorType, RigidTransform
from pydrake.multibody.inverse_kinematics import MinimumDistanceLowerBoundConstraint
from pydrake.multibody.optimization import CalcGridPointsOptions, Toppra
from pydrake.planning import KinematicTrajectoryOptimization
from pydrake.solvers import SnoptSolver
from pydrake.trajectories import (
    BsplineTrajectory,
    PathParameterizedTrajectory,
    PiecewisePolynomial,
    Trajectory,
)

from hrc_drake.motion.ik import solve_ik
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.scene import PlanningScene

# rad in every joint: a free move this short is the straight line in joint space (`free_path`).
SHORT_MOVE = 0.05


class PlanningError(RuntimeError):
    """A path between two reachable postures could not be found or retimed."""


@dataclass(frozen=True)
class JointLimits:
    """The UR3's joint limits used by the optimisers and the validator."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    @staticmethod
    def of(scene: PlanningScene, options: MotionOptions) -> JointLimits:
        """From the model (positions, velocities) and the options (acceleration)."""
        plant = scene.plant
        velocity = np.asarray(plant.GetVelocityUpperLimits(), dtype=float)
        if not np.all(np.isfinite(velocity)):
            raise ValueError("the UR3 model gives no velocity limits")
        n = plant.num_positions()
        return JointLimits(
            np.asarray(plant.GetPositionLowerLimits(), dtype=float),
            np.asarray(plant.GetPositionUpperLimits(), dtype=float),
            velocity,
            np.full(n, options.joint_acceleration_limit),
        )


def path_clearance(scene: PlanningScene, path: Trajectory, samples: int) -> tuple[float, str]:
    """Smallest robot distance along `path` at `samples` evenly spaced times, with its pair."""
    worst, pair = np.inf, ""
    for t in np.linspace(path.start_time(), path.end_time(), samples):
        d, p = scene.min_distance(path.value(t).ravel())
        if d < worst:
            worst, pair = d, p
    return worst, pair


def _keeps_clearance(scene: PlanningScene, path: Trajectory, options: MotionOptions) -> bool:
    """Whether `path` stays `options.clearance` from everything at its check samples."""
    return path_clearance(scene, path, options.check_samples)[0] >= options.clearance


def free_path(
    scene: PlanningScene,
    q_start: np.ndarray,
    q_end: np.ndarray,
    limits: JointLimits,
    options: MotionOptions,
) -> tuple[BsplineTrajectory, bool]:
    """A collision-free KTO path between two postures at rest, and whether it needed collision
    constraints.

    Solved with SNOPT first without collision constraints; when that path comes closer than the
    clearance plus margin (checked at `check_samples` points), solved again from it with
    minimum-distance constraints (bound: clearance + margin) at `collision_samples` points.
    A move of less than `SHORT_MOVE` in every joint is the straight line in joint space, when
    that keeps the clearance: KTO's path-length cost has no gradient at zero length, and SNOPT
    ran out of iterations on a 0.011 rad move (a swap turned just past the lift's end, whose
    way back starts almost at the pre-place above the tray). Where KTO fails without collision
    constraints, the straight line is taken too if it keeps the clearance.
    """
    order = 4
    base_duration = float(np.max(np.abs(q_end - q_start) / limits.velocity)) * 2.0 + 0.5
    line = _joint_line(q_start, q_end, base_duration, order, options.kto_control_points)
    line_clear = None  # whether the straight line keeps the clearance, once checked
    if float(np.max(np.abs(q_end - q_start))) < SHORT_MOVE:
        line_clear = _keeps_clearance(scene, line, options)
        if line_clear:
            return line, False
    trajopt = _kto(q_start, q_end, limits, options, order)
    solver = SnoptSolver()
    result = _solve_from_line(trajopt, solver, line, base_duration, order, options)
    if not result.is_success():
        if line_clear is None:
            line_clear = _keeps_clearance(scene, line, options)
        if line_clear:
            return line, False
        raise PlanningError(f"KTO without collisions failed: {result.get_solution_result()}")
    path = trajopt.ReconstructTrajectory(result)
    target = options.clearance + options.clearance_margin
    worst, pair = path_clearance(scene, path, options.check_samples)
    if worst >= target:
        return path, False
    return _solve_with_collisions(scene, trajopt, solver, path, (worst, pair), options), True


def _kto(
    q_start: np.ndarray,
    q_end: np.ndarray,
    limits: JointLimits,
    options: MotionOptions,
    order: int,
) -> KinematicTrajectoryOptimization:
    """KTO from `q_start` to `q_end`, at rest at both, within the joint limits: shortest in
    time and path length, no collision constraints yet."""
    n = len(q_start)
    trajopt = KinematicTrajectoryOptimization(n, options.kto_control_points, spline_order=order)
    trajopt.AddDurationCost(1.0)
    trajopt.AddPathLengthCost(1.0)
    trajopt.AddPositionBounds(limits.lower, limits.upper)
    trajopt.AddVelocityBounds(-limits.velocity, limits.velocity)
    trajopt.AddAccelerationBounds(-limits.acceleration, limits.acceleration)
    trajopt.AddDurationConstraint(0.05, 30.0)
    trajopt.AddPathPositionConstraint(q_start, q_start, 0.0)
    trajopt.AddPathPositionConstraint(q_end, q_end, 1.0)
    zero = np.zeros(n)
    trajopt.AddPathVelocityConstraint(zero, zero, 0.0)
    trajopt.AddPathVelocityConstraint(zero, zero, 1.0)
    return trajopt


def _solve_from_line(
    trajopt: KinematicTrajectoryOptimization,
    solver: SnoptSolver,
    line: BsplineTrajectory,
    base_duration: float,
    order: int,
    options: MotionOptions,
):
    """SNOPT's result on `trajopt` from the straight line `line` as the guess, over
    `base_duration` and then slower or faster: the first success, else the last failure."""
    prog = trajopt.get_mutable_prog()
    # KTO is nonconvex (duration × velocity and acceleration bounds); when SNOPT stalls from one
    # guess, a slower or faster one usually converges.
    for scale in (1.0, 2.0, 0.5, 4.0):
        basis = BsplineBasis(
            order,
            options.kto_control_points,
            KnotVectorType.kClampedUniform,
            0.0,
            base_duration * scale,
        )
        trajopt.SetInitialGuess(BsplineTrajectory(basis, line.control_points()))
        result = solver.Solve(prog)
        if result.is_success():
            break
    return result


def _solve_with_collisions(
    scene: PlanningScene,
    trajopt: KinematicTrajectoryOptimization,
    solver: SnoptSolver,
    path: BsplineTrajectory,
    closest: tuple[float, str],
    options: MotionOptions,
) -> BsplineTrajectory:
    """`trajopt` solved again from `path` (whose `closest` distance and pair fall short of the
    clearance plus margin) with minimum-distance constraints at `collision_samples` points,
    then twice as many: the first path keeping the clearance. PlanningError when neither does."""
    prog = trajopt.get_mutable_prog()
    target = options.clearance + options.clearance_margin
    worst, pair = closest
    samples = options.collision_samples
    for _ in range(2):
        constraint = MinimumDistanceLowerBoundConstraint(
            scene.plant, target, scene.plant_context, None, 0.02
        )
        for s in np.linspace(0.0, 1.0, samples):
            trajopt.AddPathPositionConstraint(constraint, s)
        trajopt.SetInitialGuess(path)
        result = solver.Solve(prog)
        if result.is_success():
            path = trajopt.ReconstructTrajectory(result)
            worst, pair = path_clearance(scene, path, options.check_samples)
            if worst >= options.clearance:
                return path
        samples *= 2
    raise PlanningError(
        f"KTO with collision constraints failed ({result.get_solution_result()}); "
        f"closest pair {pair} at {worst:.4f} m"
    )


def _joint_line(
    q_start: np.ndarray, q_end: np.ndarray, duration: float, order: int, points: int
) -> BsplineTrajectory:
    """The straight line from `q_start` to `q_end` in joint space as a B-spline over
    [0, `duration`] (KTO's initial guess, and the path of a short move)."""
    basis = BsplineBasis(order, points, KnotVectorType.kClampedUniform, 0.0, duration)
    n = len(q_start)
    control = [(q_start + (q_end - q_start) * a).reshape(n, 1) for a in np.linspace(0, 1, points)]
    return BsplineTrajectory(basis, control)


def straight_waypoints(
    scene: PlanningScene,
    q_start: np.ndarray,
    X_W_end: RigidTransform,
    options: MotionOptions,
    *,
    task: str,
    waypoint: str,
) -> list[np.ndarray]:
    """Postures moving the tcp on a straight line from its pose at q_start to X_W_end.

    Each IK waypoint is seeded with, and pulled towards, the previous one.
    """
    X_W_start = scene.tcp_pose(q_start)
    p0, p1 = X_W_start.translation(), X_W_end.translation()
    qs = [np.asarray(q_start, dtype=float)]
    for a in np.linspace(0.0, 1.0, options.straight_steps + 1)[1:]:
        X = RigidTransform(X_W_end.rotation(), p0 + a * (p1 - p0))
        qs.append(
            solve_ik(
                scene,
                X,
                [qs[-1]],
                qs[-1],
                min_distance=options.clearance,
                task=task,
                waypoint=waypoint,
            )
        )
    return qs


def spline_through(qs: list[np.ndarray]) -> PiecewisePolynomial:
    """A cubic path over s ∈ [0, 1] through postures, at rest at both ends (so reversing the
    postures reverses the path)."""
    breaks = np.linspace(0.0, 1.0, len(qs))
    zero = np.zeros(len(qs[0]))
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(
        breaks, np.column_stack(qs), zero, zero
    )


@dataclass(frozen=True)
class Retimed:
    """A path with Toppra's time-optimal parameterisation, slowed to `fraction` of the limits.

    Attributes:
        path: the geometric path q(s).
        s_of_t: Toppra's time-optimal s(t) over [0, optimal_duration].
        fraction: the plan runs at time t = t_optimal / fraction.
        reverse: run the path backwards (symmetric limits: the reversed time-optimal motion is
            the time-optimal motion of the reversed path).
    """

    path: Trajectory
    s_of_t: PiecewisePolynomial
    fraction: float
    reverse: bool = False

    @property
    def optimal_duration(self) -> float:
        """Toppra's time-optimal duration under the full limits."""
        return self.s_of_t.end_time() - self.s_of_t.start_time()

    @property
    def duration(self) -> float:
        """The duration the plan uses."""
        return self.optimal_duration / self.fraction

    @property
    def end(self) -> np.ndarray:
        """The posture at the end of the motion."""
        s = self.path.start_time() if self.reverse else self.path.end_time()
        return np.asarray(self.path.value(s)).ravel()

    def reversed(self) -> Retimed:
        """The same motion run backwards."""
        return replace(self, reverse=not self.reverse)

    def trajectory(self) -> PathParameterizedTrajectory:
        """The motion as one exact trajectory over [0, duration]: the path under Toppra's time
        scaling, slowed by `fraction` (and reversed for a reversed motion); no resampling."""
        s_of_t = copy.deepcopy(self.s_of_t)
        s_of_t.shiftRight(-s_of_t.start_time())
        if self.reverse:
            s_of_t.ReverseTime()
            s_of_t.shiftRight(self.optimal_duration)
        s_of_t.ScaleTime(1.0 / self.fraction)
        return PathParameterizedTrajectory(self.path, s_of_t)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) at plan time t ∈ [0, duration]."""
        if self.reverse:
            q, q_dot = replace(self, reverse=False).sample(self.duration - t)
            return q, -q_dot
        t_opt = self.s_of_t.start_time() + float(
            np.clip(t * self.fraction, 0, self.optimal_duration)
        )
        s = float(self.s_of_t.value(t_opt)[0, 0])
        s = float(np.clip(s, self.path.start_time(), self.path.end_time()))
        s_dot = float(self.s_of_t.EvalDerivative(t_opt, 1)[0, 0])
        q = self.path.value(s).ravel()
        q_dot = self.path.EvalDerivative(s, 1).ravel() * s_dot * self.fraction
        return q, q_dot


def time_optimal(
    scene: PlanningScene,
    path: Trajectory,
    limits: JointLimits,
    options: MotionOptions,
    min_grid_points: int | None = None,
) -> Trajectory | None:
    """Toppra's time-optimal s(t) along `path` under the joint velocity and acceleration limits
    and the tcp speed limit; None if Toppra finds none."""
    grid_options = CalcGridPointsOptions()
    if min_grid_points is not None:
        grid_options.min_points = min_grid_points
    toppra = Toppra(path, scene.plant, Toppra.CalcGridPoints(path, grid_options))
    toppra.AddJointVelocityLimit(-limits.velocity, limits.velocity)
    toppra.AddJointAccelerationLimit(-limits.acceleration, limits.acceleration)
    toppra.AddFrameTranslationalSpeedLimit(scene.tcp_frame, options.tcp_speed_limit)
    return toppra.SolvePathParameterization()


def retime(
    scene: PlanningScene, path: Trajectory, limits: JointLimits, options: MotionOptions
) -> Retimed:
    """Toppra's time-optimal parameterisation (`time_optimal`); the plan then runs it uniformly
    slower by `options.limit_fraction`."""
    s_of_t = time_optimal(scene, path, limits, options, min_grid_points=40)
    if s_of_t is None:
        path, s_of_t = _refit_and_time(scene, path, limits, options)
    if s_of_t is None:
        raise PlanningError("Toppra found no time parameterisation of the path")
    return Retimed(path, s_of_t, options.limit_fraction)


def _refit_and_time(
    scene: PlanningScene, path: Trajectory, limits: JointLimits, options: MotionOptions
) -> tuple[Trajectory, Trajectory | None]:
    """(path, s(t)) for a path Toppra cannot time: now and then it fails on a KTO path at any
    grid ("failed to find the maximum path acceleration" near a knot; a 0.18 rad carry back to
    the tray, in the population sweep), and times the cubic spline through samples of the same
    path, at rest at both ends, which is taken if it keeps the clearance. (path, None) when no
    refit does."""
    for count in (8, 12, 16, 24, 40):
        times = np.linspace(path.start_time(), path.end_time(), count)
        refit = spline_through([path.value(t).ravel() for t in times])
        if not _keeps_clearance(scene, refit, options):
            continue
        s_of_t = time_optimal(scene, refit, limits, options, min_grid_points=40)
        if s_of_t is not None:
            return refit, s_of_t
    return path, None
