"""Plan a task of the flange case: which part moves, where, along which collision-free path."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.trajectories import CompositeTrajectory, PiecewisePolynomial, Trajectory

from hrc_drake.cell_models import TABLE, CellDesign, CellModelError
from hrc_drake.motion.ik import UnreachableError, solve_ik
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import HOME_LEG, LIFT, CheckPhase, MotionTiming, Plan, Segment, Stage
from hrc_drake.motion.poses import (
    CellFrames,
    default_layout,
    offset_along_approach,
    part_pose,
    pose_from_values,
    pose_values,
    quantize_joints,
    quantize_opening,
    quantize_pose,
    tcp_pose,
)
from hrc_drake.motion.scene import (
    GRIPPER,
    MAX_OPENING,
    PLATE,
    TRAY,
    Layout,
    PlanningScene,
    SceneModel,
    load_cell_frames,
)
from hrc_drake.motion.trajectory import (
    JointLimits,
    PlanningError,
    Retimed,
    free_path,
    retime,
    spline_through,
    straight_waypoints,
)
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

# The UR3 "ready" posture family (ROS joint conventions): elbow up, tool pointing down.
_READY = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])
# Where home puts the tcp: above the work, between plate and tray [m above the seats].
_HOME_HEIGHT = 0.20
# A loose part lying tilted up to this from upright [rad] is grasped with the gripper tilted to
# the part's normal (its own grasp frame where it lies): the fingers close across the part's
# width, square to its faces, as in the tray. Past it the approach leans so far that the
# fingers going down along it meet what the part leans on, and the wrist's posture comes close
# to the UR3's reach over the plate; the part is handed over. (It was 0.2 rad, with a vertical
# approach in mind: a flange resting 0.21 rad tilted against the plate's edge was handed over.)
_MAX_GRASP_TILT = 0.5
# A loose part rests on, or leans against, what is this close to it [m] (measured poses are
# a little off: a part may seem to float or sink by a millimetre or two).
_RESTS_ON = 0.005


@dataclass(frozen=True)
class TaskMove:
    """What a task moves: the part instance, from where to where (None = its tray home)."""

    task: str
    instance: str
    source: str | None
    target: str | None
    before: Mapping[str, str]
    after: Mapping[str, str]


def resolve_task(
    frames: CellFrames,
    configuration: Iterable[str],
    task: str,
    last_token: str | None = None,
    layout: Mapping[str, str] | None = None,
    instance: str | None = None,
) -> TaskMove:
    """Which instance `task` moves from `configuration`, and the token assignments around it.

    `layout` (instance -> token, e.g. measured by the SlotMonitor) says which instance sits at
    each token; without it, `default_layout` gives the robot's own routine. An assembly token
    takes a part of its symbol from the tray (`instance`, or the lowest-numbered free one);
    `undo` returns the part at `last_token` (the task done last) to its tray home.
    """
    configuration = frozenset(configuration)
    if layout is None:
        layout = default_layout(frames, configuration, last_token)
    if frozenset(layout.values()) != configuration:
        raise ValueError(
            f"layout {dict(layout)} does not hold the configuration {sorted(configuration)}"
        )
    before = {token: instance for instance, token in layout.items()}
    if task == UNDO:
        if last_token is None or last_token not in configuration:
            raise ValueError(f"undo needs the last task placed (last_token), got {last_token!r}")
        if instance is not None and instance != before[last_token]:
            raise ValueError(f"undo moves {before[last_token]} (at {last_token}), not {instance}")
        after = {t: i for t, i in before.items() if t != last_token}
        return TaskMove(task, before[last_token], last_token, None, before, after)
    if task in configuration:
        raise ValueError(f"task {task} is already in place in {sorted(configuration)}")
    symbol = frames.spec.placement(task).part
    used = set(before.values())
    free = [i for i in frames.design.instances_of(symbol) if i not in used]
    if instance in used:
        seat = next(t for t, i in before.items() if i == instance)
        raise ValueError(
            f"task {task}: {instance} is not a free part, the layout has it at {seat}; pass the "
            "measured layout without the part to move"
        )
    if instance is not None:
        if instance not in free:
            raise ValueError(f"task {task} places a {symbol}: {instance} is not one ({free})")
        free = [instance]
    if not free:
        raise ValueError(f"task {task}: no {symbol} left in the tray in {sorted(configuration)}")
    after = dict(before)
    after[task] = free[0]
    return TaskMove(task, free[0], None, task, before, after)


@dataclass(frozen=True)
class _Measured:
    """A plan's measured inputs, rounded to the plan cache's resolution: the part named, the
    7 pose values where it lies, the joint positions the arm starts from (None: the lowest
    free instance; its tray home or seat; `q_home`), the 7 pose values of an obstacle in the
    cell (): none)."""

    instance: str | None = None
    source: tuple[float, ...] | None = None
    start: tuple[float, ...] | None = None
    obstacle: tuple[float, ...] = ()
    held: bool = False  # the part is in the gripper at `start` already
    start_opening: float | None = None  # the gripper's opening at `start` (None: the pick's)


@dataclass(frozen=True)
class _Given:
    """`plan_task`'s measured keywords as given (before rounding)."""

    instance: str | None = None
    source_pose: RigidTransform | None = None
    q_start: np.ndarray | None = None
    obstacle: RigidTransform | None = None
    held: bool = False
    start_opening: float | None = None


@dataclass(frozen=True)
class _Pick:
    """The pick half of a plan: its scene, the pre-grasp posture, the free path there (with
    whether it needed collision constraints), the straight way down to the grasp, and the
    contacts allowed going down (`hand`) and lifting the part (`lift`)."""

    scene: PlanningScene
    q_pregrasp: np.ndarray
    approach: tuple
    down: list[np.ndarray]
    hand: tuple[tuple[str, str], ...]
    lift: tuple[tuple[str, str], ...]
    clear: list[np.ndarray] | None = None  # straight up from a start too close to the cell
    near: tuple[tuple[str, str], ...] = ()  # the contacts allowed going up


class _Timeline:
    """Chains arm motions and still intervals into one exact trajectory (no resampling): each
    retimed move is a `PathParameterizedTrajectory`, each still interval a constant piece, and
    the plan a `CompositeTrajectory` of them."""

    def __init__(self, q0: np.ndarray, opening: float):
        self.t = 0.0
        self.q_end = np.asarray(q0, dtype=float)
        self.pieces: list[Trajectory] = []
        self.segments: list[Segment] = []
        self.phases: list[CheckPhase] = []
        self.motions: list[MotionTiming] = []
        self.gripper_times = [0.0]
        self.gripper_values = [opening]

    def move(self, name: str, retimed: Retimed, free: tuple | None = None) -> None:
        self.pieces.append(retimed.trajectory())
        self.q_end = retimed.end
        kto, constrained = (None, False) if free is None else (free[0].end_time(), free[1])
        self.motions.append(
            MotionTiming(name, self.t, retimed.duration, retimed.optimal_duration, kto, constrained)
        )
        self.t += retimed.duration

    def wait(self, duration: float) -> None:
        if duration <= 0.0:
            return
        q = self.q_end.reshape(-1, 1)
        self.pieces.append(PiecewisePolynomial.ZeroOrderHold([0.0, duration], np.hstack([q, q])))
        self.t += duration

    def gripper(self, opening: float, duration: float) -> None:
        self.gripper_times.append(self.t)
        self.gripper_values.append(self.gripper_values[-1])
        self.wait(duration)
        self.gripper_times.append(self.t)
        self.gripper_values.append(opening)

    def ramp_gripper(self, since: float, opening: float) -> None:
        """The gripper goes to `opening` over the arm's motions since plan time `since` (no
        wait: the fingers move while the arm does)."""
        self.gripper_times += [since, self.t]
        self.gripper_values += [self.gripper_values[-1], opening]

    def stage(self, stage: Stage, start: float) -> None:
        self.segments.append(Segment(stage, start, self.t))

    def phase(self, start: float, layout: Layout, allowed: tuple[tuple[str, str], ...]) -> None:
        self.phases.append(CheckPhase(start, self.t, layout, allowed))

    def trajectory(self) -> CompositeTrajectory:
        return CompositeTrajectory.AlignAndConcatenate(self.pieces)

    def gripper_trajectory(self) -> PiecewisePolynomial:
        times = [*self.gripper_times, self.t]
        values = [*self.gripper_values, self.gripper_values[-1]]
        keep = [0] + [i for i in range(1, len(times)) if times[i] > times[i - 1] + 1e-9]
        return PiecewisePolynomial.FirstOrderHold(
            np.array([times[i] for i in keep]), np.array([[values[i] for i in keep]])
        )


class MotionPlanner:
    """Plans the robot's motion for tasks of the flange case, caching scenes and plans.

    Plans start and end at the home posture `q_home` (default: the tcp pointing down 0.2 m above
    the seats, halfway between the plate and the tray); a re-plan may start at a measured
    posture and pick its part where it was measured lying. Scenes are cached by layout; plans
    by (task, which instance sits at each token, the token moved): for the flange case, that is
    (configuration, task) plus, for undo, the last task; and a re-plan's part, pose and start.
    """

    def __init__(
        self,
        options: MotionOptions | None = None,
        frames: CellFrames | None = None,
        q_home: np.ndarray | None = None,
        design: CellDesign | None = None,
    ):
        self.options = options or MotionOptions()
        if frames is None:
            frames = load_cell_frames(design or CellDesign.of(load_spec()))
        self.frames = frames
        self._models: dict[str | None, SceneModel] = {}
        self._scenes: dict[Layout, PlanningScene] = {}
        self._plans: dict[tuple, Plan] = {}
        empty = self.scene(Layout.of({}, None, MAX_OPENING))
        self.limits = JointLimits.of(empty, self.options)
        self._rng = np.random.default_rng(self.options.seed)
        if q_home is None:
            try:
                q_home = self._home(empty)
            except UnreachableError as err:
                layout = self.frames.design.layout
                raise CellModelError(
                    f"the UR3 cannot reach its home pose above the work ({err}); the plate and "
                    "the tray are too far: move them closer (cell.plate_position "
                    f"{layout.plate_position}, cell.tray_position)"
                ) from err
        self.q_home = np.asarray(q_home, dtype=float)

    def scene(self, layout: Layout) -> PlanningScene:
        """The planning scene of a layout (built once)."""
        if layout not in self._scenes:
            if layout.carried not in self._models:
                self._models[layout.carried] = SceneModel(self.frames, layout.carried)
            self._scenes[layout] = PlanningScene(self._models[layout.carried], layout)
        return self._scenes[layout]

    def _down_rotation(self) -> RotationMatrix:
        instance = next(iter(self.frames.grasps))
        return tcp_pose(self.frames, instance, self.frames.homes[instance]).rotation()

    def _toward(self, scene: PlanningScene, p_W: np.ndarray) -> np.ndarray:
        """The ready posture with the shoulder pan turned toward a point."""
        p0 = scene.tcp_pose(_READY).translation()
        q = _READY.copy()
        q[0] = np.arctan2(p_W[1], p_W[0]) - np.arctan2(p0[1], p0[0])
        return q

    def _home(self, scene: PlanningScene) -> np.ndarray:
        seats = np.array([X.translation() for X in self.frames.seats.values()])
        homes = np.array([X.translation() for X in self.frames.homes.values()])
        p = 0.5 * (seats.mean(axis=0) + homes.mean(axis=0))
        p[2] = float(np.max(seats[:, 2])) + _HOME_HEIGHT
        nominal = self._toward(scene, p)
        X = RigidTransform(self._down_rotation(), p)
        return solve_ik(
            scene, X, [nominal], nominal, min_distance=0.012, task="home", waypoint="home"
        )

    def _seeds(self, scene: PlanningScene, X: RigidTransform, previous: np.ndarray) -> list:
        nominal = self._toward(scene, X.translation())
        seeds = [previous, nominal, self.q_home]
        for _ in range(3):
            seeds.append(nominal + self._rng.normal(0.0, 0.3, size=len(nominal)))
        return seeds

    def _ik(self, scene, X, previous, task, waypoint) -> np.ndarray:
        nominal = self._toward(scene, X.translation())
        margin = self.options.clearance + self.options.clearance_margin
        return solve_ik(
            scene,
            X,
            self._seeds(scene, X, previous),
            nominal,
            min_distance=margin,
            task=task,
            waypoint=waypoint,
        )

    def _support(self, token: str | None, placed: Mapping[str, str]) -> str:
        """The model instance a part rests on at `token` (None: the tray), given the tokens in
        place -> their instances."""
        if token is None:
            return TRAY
        spec = self.frames.spec
        placement = spec.placement(token)
        if placement.host is None:
            return PLATE
        for other, instance in placed.items():
            host = spec.placement(other)
            if (
                host.part == placement.host
                and host.host is None
                and placement.slots[0] in host.slots
            ):
                return instance
        raise ValueError(f"{token}: no {placement.host} under it in {sorted(placed)}")

    def plan_task(
        self,
        configuration: Iterable[str],
        task: str,
        *,
        last_token: str | None = None,
        layout: Mapping[str, str] | None = None,
        instance: str | None = None,
        source_pose: RigidTransform | None = None,
        q_start: np.ndarray | None = None,
        obstacle: RigidTransform | None = None,
        held: bool = False,
        start_opening: float | None = None,
    ) -> Plan:
        """The plan of `task` from `configuration` (the tokens in place), home to home.

        `last_token` is the task done last; `undo` needs it (the part placed last goes back to
        its tray home). `layout` (instance -> token) is where each part physically is, as the
        cell measured it; without it the robot's own routine is assumed (`default_layout`).
        `instance` is the part an assembly task moves (default: the lowest-numbered free one);
        with `source_pose` (X_W_part, measured: on the table, plate, tray or other parts) it is
        picked where it lies instead of from its tray home, and is not in `layout`. `q_start`
        (the UR3's 6 joint positions) starts the plan there instead of at `q_home`; it still
        ends at `q_home`. `obstacle` is the world pose of a temporary obstacle the cell measures
        (`hrc_drake.obstacle_models`): the plan keeps clear of it. Measured values are rounded
        to the plan cache's resolution (`poses.KEY_DIGITS`) before planning, so that the plan is
        a function of its cache key. With `held`, `instance` is already in the gripper, grasped,
        the arm at `q_start` (a robot that started on another task: a re-target): the plan
        carries it from there to `task`'s seat, or with `task` `undo` back to its tray home
        (a swap: the part is put back), then home; it has no pick (its approach and grasp
        stages last no time).
        Raises UnreachableError (naming the task and the violated constraint) when a pose is out
        of reach or a part lies too tilted to be grasped from above, PlanningError when no path
        is found (or the start posture is not clear of the cell), ValueError for arguments that
        do not fit (a source pose for `undo` or without its instance, a seated instance).
        """
        configuration = frozenset(configuration)
        move, measured = self._resolve(
            configuration,
            task,
            last_token,
            layout,
            _Given(instance, source_pose, q_start, obstacle, held, start_opening),
        )
        key = self._key(move, measured)
        if key not in self._plans:
            self._rng = np.random.default_rng(self.options.seed)
            self._plans[key] = self._plan(configuration, move, measured)
        return self._plans[key]

    def has_plan(
        self,
        configuration: Iterable[str],
        task: str,
        *,
        last_token: str | None = None,
        layout: Mapping[str, str] | None = None,
        instance: str | None = None,
        source_pose: RigidTransform | None = None,
        q_start: np.ndarray | None = None,
        obstacle: RigidTransform | None = None,
        held: bool = False,
        start_opening: float | None = None,
    ) -> bool:
        """Whether `plan_task` with these arguments would return a plan made earlier."""
        move, measured = self._resolve(
            frozenset(configuration),
            task,
            last_token,
            layout,
            _Given(instance, source_pose, q_start, obstacle, held, start_opening),
        )
        return self._key(move, measured) in self._plans

    def _resolve(
        self, configuration, task, last_token, layout, given: _Given
    ) -> tuple[TaskMove, _Measured]:
        """`plan_task`'s arguments as the move and its rounded measured inputs."""
        instance, source_pose, q_start, obstacle = (
            given.instance,
            given.source_pose,
            given.q_start,
            given.obstacle,
        )
        if given.held:
            move = self._held_move(configuration, task, last_token, layout, given)
        elif source_pose is not None and task == UNDO:
            raise ValueError(
                "undo takes the part placed last from its seat; a source pose is for assembly "
                "tasks (plan the part's placement from where it lies instead)"
            )
        elif source_pose is not None and instance is None:
            raise ValueError(f"task {task}: a source pose needs the part lying there (instance=)")
        else:
            move = resolve_task(self.frames, configuration, task, last_token, layout, instance)
        measured = _Measured(
            instance,
            None if source_pose is None else quantize_pose(pose_values(source_pose)),
            None if q_start is None else quantize_joints(q_start, len(self.q_home)),
            () if obstacle is None else quantize_pose(pose_values(obstacle)),
            given.held,
            None
            if given.start_opening is None or q_start is None or given.held
            else quantize_opening(given.start_opening),
        )
        return move, measured

    def _held_move(self, configuration, task, last_token, layout, given: _Given) -> TaskMove:
        """The move of a part already in the gripper: to `task`'s seat, or (`undo`) home."""
        if given.instance is None or given.q_start is None:
            raise ValueError(f"task {task}: a held part needs its instance and q_start")
        if given.source_pose is not None:
            raise ValueError(f"task {task}: a held part is in the gripper, not lying somewhere")
        if task != UNDO:
            return resolve_task(
                self.frames, configuration, task, last_token, layout, given.instance
            )
        if layout is None:
            layout = default_layout(self.frames, configuration, last_token)
        before = {token: inst for inst, token in layout.items()}
        if given.instance in before.values():
            raise ValueError(f"{given.instance} is placed in the layout, not held")
        return TaskMove(UNDO, given.instance, None, None, before, before)

    @staticmethod
    def _key(move: TaskMove, measured: _Measured) -> tuple:
        # Which part sits where, and which one moves: all a plan depends on; and, when given,
        # the part named, where it lies and the posture the arm starts from.
        key = (move.task, frozenset(move.before.items()), move.source)
        if measured == _Measured():
            return key
        return (
            *key,
            move.instance,
            measured.source,
            measured.start,
            measured.obstacle,
            measured.held,
            measured.start_opening,
        )

    def _loose_grasps(
        self, task: str, part: str, X_W_part: RigidTransform
    ) -> tuple[RigidTransform, ...]:
        """The tcp poses grasping `part` lying at a measured X_W_part: its grasp frame there,
        and that turned a half turn about the approach axis (the parts are symmetric under it),
        the one closer to the grasp at the part's tray home first, so that the wrist does not
        wind; the other is tried when the first is out of reach (a tilted grasp often is).
        The grasp tilts with the part (up to `_MAX_GRASP_TILT`), so the fingers close across
        its width as in the tray; UnreachableError when the part lies more tilted, or is
        wider than the gripper's stroke (its IK and the fingers' way down are checked after)."""
        frames = self.frames
        X_W_home = frames.homes[part]
        up = X_W_home.rotation().col(2)  # a part lies upright in its tray home
        tilt = float(np.arccos(np.clip(X_W_part.rotation().col(2) @ up, -1.0, 1.0)))
        if tilt > _MAX_GRASP_TILT:
            raise UnreachableError(
                task,
                "grasp",
                "orientation",
                f"{part} lies tilted {tilt:.2f} rad from upright; the gripper grasps a loose "
                f"part tilted with it, up to {_MAX_GRASP_TILT} rad",
            )
        width = frames.widths[part] + 2.0 * self.options.finger_gap
        if width > MAX_OPENING:  # the width across the grasp is the part's, at any tilt
            raise UnreachableError(
                task,
                "grasp",
                "stroke",
                f"{part} needs {width * 1000:.0f} mm between the fingers, past the RG2's "
                f"{MAX_OPENING * 1000:.0f} mm stroke",
            )
        X_grasp = tcp_pose(frames, part, X_W_part)
        turned = X_grasp @ RigidTransform(RotationMatrix.MakeZRotation(np.pi))
        R_home_inv = tcp_pose(frames, part, X_W_home).rotation().inverse()

        def wind(X: RigidTransform) -> float:
            return (R_home_inv @ X.rotation()).ToAngleAxis().angle()

        # Both hold the part in its own grasp frame, so that the place half (which seats the
        # part held so) serves them. A level grasp straddling a tilted part would hold it tilted
        # between the fingers and seat it so: not offered.
        return tuple(sorted((X_grasp, turned), key=wind))

    def _check_start(self, scene: PlanningScene, q: np.ndarray, task: str) -> None:
        """A start posture other than home must be within the joint limits and clear of the
        cell by the optimisers' margin: the free path's collision constraints hold at its start
        too."""
        limits, opts = self.limits, self.options
        outside = np.flatnonzero((q < limits.lower) | (q > limits.upper))
        if outside.size:
            raise PlanningError(
                f"task {task}: the start posture {np.round(q, 4).tolist()} is past joint "
                f"{int(outside[0]) + 1}'s limits; start from a posture within them"
            )
        need = opts.clearance + opts.clearance_margin
        distance, pair = scene.min_distance(q)
        if distance < need:
            raise PlanningError(
                f"task {task}: the start posture is {distance * 1000:.1f} mm from {pair}; a "
                f"plan starts {need * 1000:.0f} mm clear at least: move the arm clear first"
            )

    def _pick(
        self, move: TaskMove, measured: _Measured, opening: float, q_start: np.ndarray
    ) -> _Pick:
        """The pick half of `move`: from `q_start` to the pre-grasp and down to the grasp, with
        the part in its tray home, at its seat, or lying where it was measured."""
        opts, frames, task, part = self.options, self.frames, move.task, move.instance
        if measured.source is None:
            X_src = (
                frames.homes[part]
                if move.source is None
                else part_pose(frames, move.source, move.before.keys())
            )
            scene = self.scene(Layout.of(move.before, None, opening, obstacle=measured.obstacle))
            X_grasp = tcp_pose(frames, part, X_src)
            supports = (self._support(move.source, move.before),)
        else:
            X_src = pose_from_values(measured.source)
            candidates = self._loose_grasps(task, part, X_src)
            X_grasp = candidates[0]
            scene = self.scene(
                Layout.of(move.before, None, opening, {part: X_src}, measured.obstacle)
            )
            # It lies on the table, the plate or the tray, or on or against other parts.
            others = [i for i in frames.design.instance_names if i != part]
            supports = (PLATE, TRAY, TABLE, *scene.near(part, others, _RESTS_ON))
        # Near the grasp instant the fingertips come within a few mm of the surface the part
        # rests on (they hold a 10 mm part), and the part touches it.
        hand = ((GRIPPER, part), *((GRIPPER, s) for s in supports))
        lift = tuple(pair for s in supports for pair in ((part, s), (GRIPPER, s)))
        X_pregrasp = offset_along_approach(X_grasp, opts.approach_distance)
        scene.set_allowed_contacts(())
        clear, near = None, ()
        if measured.start is not None:
            clear, near = self._clear_start(scene, q_start, task)
            q_start = q_start if clear is None else clear[-1]
            self._check_start(scene, q_start, task)
        try:
            q_pregrasp = self._ik(scene, X_pregrasp, q_start, task, "pre-grasp")
        except UnreachableError:
            if measured.source is None:
                raise
            X_grasp, X_pregrasp, q_pregrasp = self._reach_loose(scene, candidates, q_start, task)
        approach = free_path(scene, q_start, q_pregrasp, self.limits, opts)
        scene.set_allowed_contacts(hand)
        down = straight_waypoints(scene, q_pregrasp, X_grasp, opts, task=task, waypoint="grasp")
        if measured.source is not None:
            self._check_fingers_clear(scene, part, down, task)
        scene.set_allowed_contacts(())
        return _Pick(scene, q_pregrasp, approach, down, hand, lift, clear, near)

    def _reach_loose(self, scene, candidates, q_start, task: str):
        """(grasp, pre-grasp, posture there) of the first of a loose part's grasps (in order)
        whose pre-grasp the wrist reaches: at the approach distance, else at half of it (a
        tilted grasp's approach leans, and backing off along it soon takes the tcp past the
        UR3's reach: a flange resting 0.39 rad tilted on the plate's edge is reached 30 mm back,
        not 60). UnreachableError from the last tried when none is."""
        distance = self.options.approach_distance
        tries = [(X, d) for d in (distance, distance / 2) for X in candidates]
        for k, (X_grasp, d) in enumerate(tries, start=1):
            X_pregrasp = offset_along_approach(X_grasp, d)
            try:
                return X_grasp, X_pregrasp, self._ik(scene, X_pregrasp, q_start, task, "pre-grasp")
            except UnreachableError:
                if k == len(tries):
                    raise
        raise AssertionError("unreachable")  # the loop returns or raises

    @staticmethod
    def _check_fingers_clear(scene: PlanningScene, part: str, down: list, task: str) -> None:
        """UnreachableError when, going down to a part lying loose, the gripper would touch
        what the part lies on (allowed near it, not into it: a part lying askew on the tray may
        leave no room for a finger beside it)."""
        scene.set_allowed_contacts(((GRIPPER, part),))
        for q in down:
            gap, pair = scene.min_distance(q, max_distance=0.01)
            if gap <= 0.0 and GRIPPER in pair:
                raise UnreachableError(
                    task,
                    "grasp",
                    "collision",
                    f"{part} lies where the fingers going down to it would touch the cell ({pair})",
                )

    def _clear_start(self, scene: PlanningScene, q: np.ndarray, task: str):
        """(postures, allowed contacts) moving the tcp straight up by the approach distance
        from a start posture closer to the cell than the optimisers' margin (the arm stopped
        with its fingers by a part or a surface), or (None, ()) when the start is clear."""
        opts = self.options
        if scene.min_distance(q)[0] >= opts.clearance + opts.clearance_margin:
            return None, ()
        X = scene.tcp_pose(q)
        up_by = np.array([0.0, 0.0, opts.approach_distance])
        X_up = RigidTransform(X.rotation(), X.translation() + up_by)
        near = tuple(
            (GRIPPER, other) for other in (PLATE, TRAY, TABLE, *self.frames.design.instance_names)
        )
        scene.set_allowed_contacts(near)
        up = straight_waypoints(scene, q, X_up, opts, task=task, waypoint="clear of the cell")
        scene.set_allowed_contacts(())
        return up, near

    def _plan(self, configuration: frozenset[str], move: TaskMove, measured: _Measured) -> Plan:
        opts, part = self.options, move.instance
        width = self.frames.widths[part]
        opening = float(min(MAX_OPENING, width + 2.0 * opts.finger_gap))
        q_start = self.q_home if measured.start is None else np.array(measured.start)
        carry = self.scene(Layout.of(move.before, part, width, obstacle=measured.obstacle))
        if measured.held:  # in the gripper already: no pick
            line = _Timeline(q_start, width - opts.grip_squeeze)
            line.stage(Stage.APPROACH, 0.0)
            line.stage(Stage.GRASP, 0.0)
            q_from = q_start
        else:
            pick = self._pick(move, measured, opening, q_start)
            start_opening = opening if measured.start_opening is None else measured.start_opening
            line = _Timeline(q_start, start_opening)
            self._pick_into(
                line, pick, carry, width, "home" if measured.start is None else "start", opening
            )
            q_from = pick.q_pregrasp
        return self._place_into(line, configuration, move, measured, carry, q_from)

    def _timed(self, scene: PlanningScene, path) -> Retimed:
        return retime(scene, path, self.limits, self.options)

    def _pick_into(
        self, line: _Timeline, pick: _Pick, carry, width: float, start: str, opening: float
    ) -> None:
        """The pick half on `line`: (clear of the cell,) to the pre-grasp, down, grasp, lift;
        the carry stage starts with the lift (it ends in `_place_into`). A gripper that starts
        at another opening than the pick's keeps it until the arm is clear of the cell (its
        fingers may be by a part it went for), then opens or closes to `opening` on the way to
        the pre-grasp (or there, if that way is too short for the fingers)."""
        timed = self._timed
        t0 = line.t
        if pick.clear is not None:
            line.move("up, clear of the cell", timed(pick.scene, spline_through(pick.clear)))
            line.phase(t0, pick.scene.layout, pick.near)
        t1 = line.t
        line.move(f"{start} to pre-grasp", timed(pick.scene, pick.approach[0]), pick.approach)
        line.phase(t1, pick.scene.layout, ())
        if abs(line.gripper_values[-1] - opening) > 1e-9:
            if line.t - t1 >= self.options.gripper_time:
                line.ramp_gripper(t1, opening)
            else:
                line.gripper(opening, self.options.gripper_time)
        t1 = line.t
        descend = timed(pick.scene, spline_through(pick.down))
        line.move("down to grasp", descend)
        line.phase(t1, pick.scene.layout, pick.hand)
        line.stage(Stage.APPROACH, t0)

        t0 = line.t
        line.gripper(width - self.options.grip_squeeze, self.options.gripper_time)
        line.phase(t0, pick.scene.layout, pick.hand)
        line.stage(Stage.GRASP, t0)

        t0 = line.t
        line.move(LIFT, descend.reversed())
        line.phase(t0, carry.layout, pick.lift)

    def _place_into(self, line, configuration, move: TaskMove, measured, carry, q_from) -> Plan:
        """The place half on `line`, from `q_from` (the part held): carry to the pre-place,
        down, hold, release, retreat, home; the finished plan."""
        opts, frames, task, part = self.options, self.frames, move.task, move.instance
        width = frames.widths[part]
        opening = float(min(MAX_OPENING, width + 2.0 * opts.finger_gap))
        X_dst = (
            frames.homes[part]
            if move.target is None
            else part_pose(frames, move.target, move.after.keys())
        )
        X_place = tcp_pose(frames, part, X_dst)
        placed = self.scene(Layout.of(move.after, None, opening, obstacle=measured.obstacle))
        # Near the place instant, as near the grasp: the part on its target, the fingers by it.
        target = self._support(move.target, move.after)
        place_allowed = ((part, target), (GRIPPER, target))
        release = ((GRIPPER, part), (GRIPPER, target))

        carry.set_allowed_contacts(())
        X_preplace = offset_along_approach(X_place, opts.approach_distance)
        q_preplace = self._ik(carry, X_preplace, q_from, task, "pre-place")
        transfer = free_path(carry, q_from, q_preplace, self.limits, opts)
        carry.set_allowed_contacts(place_allowed)
        lower = straight_waypoints(carry, q_preplace, X_place, opts, task=task, waypoint="place")
        carry.set_allowed_contacts(())
        placed.set_allowed_contacts(())
        back = free_path(placed, q_preplace, self.q_home, self.limits, opts)

        t_carry = line.segments[-1].end  # the carry begins where the grasp ends (the lift)
        t1 = line.t
        line.move("carry to pre-place", self._timed(carry, transfer[0]), transfer)
        line.phase(t1, carry.layout, ())
        line.stage(Stage.CARRY, t_carry)

        t0 = line.t
        lowering = self._timed(carry, spline_through(lower))
        line.move("down to place", lowering)
        line.stage(Stage.PLACE, t0)
        t_in_place = line.t
        line.wait(opts.undo_hold_time if task == UNDO else opts.hold_time)
        line.phase(t0, carry.layout, place_allowed)
        line.stage(Stage.HOLD, t_in_place)

        t_release = line.t
        line.gripper(opening, opts.gripper_time)
        line.stage(Stage.RELEASE, t_release)
        t0 = line.t
        line.move("retreat up", lowering.reversed())
        line.phase(t_release, placed.layout, release)
        t1 = line.t
        line.move(HOME_LEG, self._timed(placed, back[0]), back)
        line.phase(t1, placed.layout, ())
        line.stage(Stage.RETREAT, t0)

        return Plan(
            task=task,
            instance=part,
            configuration=configuration,
            trajectory=line.trajectory(),
            gripper=line.gripper_trajectory(),
            t_in_place=t_in_place,
            t_release=t_release,
            duration=line.t,
            segments=tuple(line.segments),
            phases=tuple(line.phases),
            motions=tuple(line.motions),
            grip_width=width,
        )


def check_reach(planner: MotionPlanner, suggest: bool = True) -> None:
    """Check, before any simulation, that the UR3 reaches every grasp: each part in its tray home
    and at every placement the spec allows (pre-grasp and grasp, with the robot's limits and
    clearance). CellModelError naming the slot or part and the layout value to change, and with
    `suggest` a nearby layout that passed this check (`hrc_drake.motion.reach_search`)."""
    frames, spec = planner.frames, planner.frames.spec
    opts = planner.options
    layout = frames.design.layout
    empty = planner.scene(Layout.of({}, None, MAX_OPENING))
    targets: list[tuple[str, str, RigidTransform, str]] = []
    for instance, X_W_home in frames.homes.items():
        targets.append((instance, f"{instance} in its tray home", X_W_home, "cell.tray_position"))
    configurations = {}
    for token, _mount, _slots in spec.placements():
        placement = spec.placement(token)
        if placement.host is None:
            configurations[token] = frozenset()
            continue
        host = next(
            t
            for t, m, slots in spec.placements()
            if m.part == placement.host and m.on == "base" and placement.slots[0] in slots
        )
        configurations[token] = frozenset({host})
    for token, configuration in configurations.items():
        placement = spec.placement(token)
        instance = frames.design.instances_of(placement.part)[0]
        X_W_part = part_pose(frames, token, configuration | {token})
        where = f"slot {'-'.join(map(str, placement.slots))}"
        targets.append((instance, f"{token} ({where})", X_W_part, "cell.plate_position"))
    now = {
        "cell.plate_position": layout.plate_position,
        "cell.tray_position": [round(float(x), 3) for x in frames.tray.translation()],
    }
    # The fingers close around the part and near what it rests on; the arm must stay clear.
    near_hand = [*frames.design.instance_names, PLATE, TRAY]
    empty.set_allowed_contacts([(GRIPPER, other) for other in near_hand])
    try:
        for instance, what, X_W_part, knob in targets:
            X_grasp = tcp_pose(frames, instance, X_W_part)
            for waypoint, X in (
                ("pre-grasp", offset_along_approach(X_grasp, opts.approach_distance)),
                ("grasp", X_grasp),
            ):
                nominal = planner._toward(empty, X.translation())
                try:
                    solve_ik(
                        empty,
                        X,
                        [nominal, planner.q_home],
                        nominal,
                        min_distance=opts.clearance,
                        task=what,
                        waypoint=waypoint,
                    )
                except UnreachableError as err:
                    p = X.translation()
                    raise CellModelError(
                        f"the UR3 cannot reach {what}: {err.constraint} at the {waypoint} (tcp at "
                        f"[{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m, "
                        f"{float(np.hypot(p[0], p[1])):.3f} m from its base axis; it reaches "
                        f"about 0.5 m). Move it closer: change {knob} (now {now[knob]})"
                        f"{_layout_hint(planner) if suggest else ''}"
                    ) from err
    finally:
        empty.set_allowed_contacts(())


def _layout_hint(planner: MotionPlanner) -> str:
    """A layout near the planner's that passed `check_reach`, as a hint; or say none did."""
    from hrc_drake.motion.reach_search import suggest_layout

    def reaches(design: CellDesign) -> bool:
        try:
            check_reach(MotionPlanner(planner.options, design=design), suggest=False)
        except CellModelError:
            return False
        return True

    found = suggest_layout(planner.frames.design, reaches)
    if found is None:
        return "; no layout near this one passed the reach check: move the plate or tray closer"
    return f"; the reach check passes with {found.as_yaml()} (the spec's cell: section)"
