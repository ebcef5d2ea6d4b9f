"""Plan a task of the flange case: which part moves, where, along which collision-free path.

The planner holds the scenes and the plan cache, and plans the pick half (from the start to the
grasp and the lift) and the place half (the carry, place, hold, release and the way home). What
a plan is of (`task_move`), the arm's reference postures (`postures`), the grasps of a part lying
loose (`loose_grasp`) and the plan's timeline (`timeline`) are in their own modules, as is the
check that the UR3 reaches every grasp of the spec before any run (`reach_check`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.ik import UnreachableError, solve_ik
from hrc_drake.motion.loose_grasp import (
    check_fingers_clear,
    loose_grasps,
    loose_supports,
    reach_loose,
)
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import HOME_LEG, LIFT, Plan, Stage
from hrc_drake.motion.poses import (
    CellFrames,
    offset_along_approach,
    part_pose,
    pose_from_values,
    tcp_pose,
)
from hrc_drake.motion.postures import check_start, clear_start, home_posture, toward
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
from hrc_drake.motion.task_move import (
    Measured,
    MeasuredKeywords,
    TaskMove,
    plan_key,
    resolve_request,
)
from hrc_drake.motion.timeline import Timeline
from hrc_drake.motion.trajectory import (
    JointLimits,
    Retimed,
    free_path,
    retime,
    spline_through,
    straight_waypoints,
)
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

# Openings at which a loose part's closing fingers are checked, evenly from the pick's opening
# to the part's width: between two checks the pads move at most 3.4 mm down their arc and
# 1.6 mm in (the square flange, 106 to 90 mm; `hrc_drake.rg2_kinematics.pad_height`).
_CLOSING_CHECKS = 5


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
    start_scene: PlanningScene | None = None  # going up: the fingers at their start opening


@dataclass(frozen=True)
class _Place:
    """The place half of a plan: the scene once the part is released (`placed`), the opening
    the gripper releases it at, the free path to the pre-place (with whether it needed
    collision constraints), the straight way down to the place, the free path home, and the
    contacts allowed placing the part (`allowed`) and releasing it (`release`)."""

    placed: PlanningScene
    opening: float
    transfer: tuple
    lower: list[np.ndarray]
    back: tuple
    allowed: tuple[tuple[str, str], ...]
    release: tuple[tuple[str, str], ...]


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
                q_home = home_posture(self.frames, empty)
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

    def _seeds(self, scene: PlanningScene, X: RigidTransform, previous: np.ndarray) -> list:
        nominal = toward(scene, X.translation())
        seeds = [previous, nominal, self.q_home]
        for _ in range(3):
            seeds.append(nominal + self._rng.normal(0.0, 0.3, size=len(nominal)))
        return seeds

    def _ik(self, scene, X, previous, task, waypoint) -> np.ndarray:
        nominal = toward(scene, X.translation())
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
        move, measured = resolve_request(
            self.frames,
            configuration,
            task,
            last_token,
            layout,
            MeasuredKeywords(instance, source_pose, q_start, obstacle, held, start_opening),
            len(self.q_home),
        )
        key = plan_key(move, measured)
        if key not in self._plans:
            self._rng = np.random.default_rng(self.options.seed)
            self._plans[key] = self._plan(configuration, move, measured)
        return self._plans[key]

    def _pick(
        self, move: TaskMove, measured: Measured, opening: float, q_start: np.ndarray
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
            candidates = loose_grasps(frames, opts, task, part, X_src)
            X_grasp = candidates[0]
            scene = self.scene(
                Layout.of(move.before, None, opening, {part: X_src}, measured.obstacle)
            )
            # It lies on the table, the plate or the tray, or on or against other parts.
            supports = loose_supports(scene, frames, part)
        # Near the grasp instant the fingertips come within a few mm of the surface the part
        # rests on (they hold a 10 mm part), and the part touches it.
        hand = ((GRIPPER, part), *((GRIPPER, s) for s in supports))
        lift = tuple(pair for s in supports for pair in ((part, s), (GRIPPER, s)))
        X_pregrasp = offset_along_approach(X_grasp, opts.approach_distance)
        scene.set_allowed_contacts(())
        clear, near, start_scene = None, (), self._start_scene(scene, measured)
        if measured.start is not None:
            clear, near = clear_start(start_scene, q_start, opts, frames, task, then=scene)
            q_start = q_start if clear is None else clear[-1]
            for where in {id(s): s for s in (start_scene, scene)}.values():
                check_start(where, q_start, self.limits, opts, task)
        try:
            q_pregrasp = self._ik(scene, X_pregrasp, q_start, task, "pre-grasp")
        except UnreachableError:
            if measured.source is None:
                raise
            X_grasp, X_pregrasp, q_pregrasp = reach_loose(
                self._ik, opts, scene, candidates, q_start, task
            )
        approach = free_path(scene, q_start, q_pregrasp, self.limits, opts)
        scene.set_allowed_contacts(hand)
        down = straight_waypoints(scene, q_pregrasp, X_grasp, opts, task=task, waypoint="grasp")
        if measured.source is not None:
            self._check_loose_fingers(scene, move, measured, down)
        scene.set_allowed_contacts(())
        return _Pick(scene, q_pregrasp, approach, down, hand, lift, clear, near, start_scene)

    def _start_scene(self, scene: PlanningScene, measured: Measured) -> PlanningScene:
        """The pick's scene with the fingers where they start: a gripper keeps its opening
        until the arm is clear of the cell, and the RG2's pads stand lower the narrower they
        are (hrc_drake.rg2_kinematics)."""
        if measured.start is None or measured.start_opening is None:
            return scene
        return self.scene(replace(scene.layout, opening=round(measured.start_opening, 6)))

    def _check_loose_fingers(self, scene, move: TaskMove, measured: Measured, down) -> None:
        """UnreachableError when, going down to a part lying loose or closing on it, a finger
        would touch what the part lies on or beside: the RG2's pads come down on an arc as they
        close, so a finger that went down clear beside a neighbour can sweep into its top
        before it stands at the part (a regrasp tipped a flange in the tray so). The closing
        is checked at `_CLOSING_CHECKS` openings down to the part's width."""
        part = move.instance
        check_fingers_clear(scene, part, down, move.task)
        lying = {part: pose_from_values(measured.source)}
        start, width = scene.layout.opening, self.frames.widths[part]
        for opening in np.linspace(start, width, _CLOSING_CHECKS + 1)[1:]:
            closing = Layout.of(move.before, None, float(opening), lying, measured.obstacle)
            check_fingers_clear(self.scene(closing), part, down[-1:], move.task)

    def _plan(self, configuration: frozenset[str], move: TaskMove, measured: Measured) -> Plan:
        opts, part = self.options, move.instance
        width = self.frames.widths[part]
        opening = float(min(MAX_OPENING, width + 2.0 * opts.finger_gap))
        q_start = self.q_home if measured.start is None else np.array(measured.start)
        carry = self.scene(Layout.of(move.before, part, width, obstacle=measured.obstacle))
        if measured.held:  # in the gripper already: no pick
            line = Timeline(q_start, width - opts.grip_squeeze)
            line.stage(Stage.APPROACH, 0.0)
            line.stage(Stage.GRASP, 0.0)
            q_from = q_start
        else:
            pick = self._pick(move, measured, opening, q_start)
            start_opening = opening if measured.start_opening is None else measured.start_opening
            line = Timeline(q_start, start_opening)
            self._pick_into(
                line, pick, carry, width, "home" if measured.start is None else "start", opening
            )
            q_from = pick.q_pregrasp
        return self._place_into(line, configuration, move, measured, carry, q_from)

    def _timed(self, scene: PlanningScene, path) -> Retimed:
        return retime(scene, path, self.limits, self.options)

    def _pick_into(
        self, line: Timeline, pick: _Pick, carry, width: float, start: str, opening: float
    ) -> None:
        """The pick half on `line`: (clear of the cell,) to the pre-grasp, down, grasp, lift;
        the carry stage starts with the lift (it ends in `_place_into`). A gripper that starts
        at another opening than the pick's keeps it until the arm is clear of the cell (its
        fingers may be by a part it went for), then opens or closes to `opening` on the way to
        the pre-grasp (or there, if that way is too short for the fingers)."""
        timed = self._timed
        t0 = line.t
        if pick.clear is not None:
            up = pick.start_scene or pick.scene
            line.move("up, clear of the cell", timed(up, spline_through(pick.clear)))
            line.phase(t0, up.layout, pick.near)
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
        place = self._place(move, measured, carry, q_from)
        t_in_place, t_release = self._place_on(line, move.task, carry, place)
        return Plan(
            task=move.task,
            instance=move.instance,
            configuration=configuration,
            trajectory=line.trajectory(),
            gripper=line.gripper_trajectory(),
            t_in_place=t_in_place,
            t_release=t_release,
            duration=line.t,
            segments=tuple(line.segments),
            phases=tuple(line.phases),
            motions=tuple(line.motions),
            grip_width=self.frames.widths[move.instance],
        )

    def _place(self, move: TaskMove, measured: Measured, carry, q_from: np.ndarray) -> _Place:
        """The place half's paths from `q_from` (the part held, in the `carry` scene): to the
        pre-place, down to the place, and (the part released) from the pre-place home."""
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
        allowed = ((part, target), (GRIPPER, target))
        release = ((GRIPPER, part), (GRIPPER, target))

        carry.set_allowed_contacts(())
        X_preplace = offset_along_approach(X_place, opts.approach_distance)
        q_preplace = self._ik(carry, X_preplace, q_from, task, "pre-place")
        transfer = free_path(carry, q_from, q_preplace, self.limits, opts)
        carry.set_allowed_contacts(allowed)
        lower = straight_waypoints(carry, q_preplace, X_place, opts, task=task, waypoint="place")
        carry.set_allowed_contacts(())
        placed.set_allowed_contacts(())
        back = free_path(placed, q_preplace, self.q_home, self.limits, opts)
        return _Place(placed, opening, transfer, lower, back, allowed, release)

    def _place_on(
        self, line: Timeline, task: str, carry: PlanningScene, place: _Place
    ) -> tuple[float, float]:
        """The place half's motions on `line`: carry, down, hold, release, retreat, home.
        (The plan time the part is in place, the plan time of the release.)"""
        opts, placed = self.options, place.placed
        t_carry = line.segments[-1].end  # the carry begins where the grasp ends (the lift)
        t1 = line.t
        line.move("carry to pre-place", self._timed(carry, place.transfer[0]), place.transfer)
        line.phase(t1, carry.layout, ())
        line.stage(Stage.CARRY, t_carry)

        t0 = line.t
        lowering = self._timed(carry, spline_through(place.lower))
        line.move("down to place", lowering)
        line.stage(Stage.PLACE, t0)
        t_in_place = line.t
        line.wait(opts.undo_hold_time if task == UNDO else opts.hold_time)
        line.phase(t0, carry.layout, place.allowed)
        line.stage(Stage.HOLD, t_in_place)

        t_release = line.t
        line.gripper(place.opening, opts.gripper_time)
        line.stage(Stage.RELEASE, t_release)
        t0 = line.t
        line.move("retreat up", lowering.reversed())
        line.phase(t_release, placed.layout, place.release)
        t1 = line.t
        line.move(HOME_LEG, self._timed(placed, place.back[0]), place.back)
        line.phase(t1, placed.layout, ())
        line.stage(Stage.RETREAT, t0)
        return t_in_place, t_release
