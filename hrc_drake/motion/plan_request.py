"""What a controller asks the plan service, and what it gets back: a `PlanRequest` (what a task
plan depends on, as plain values), a `PlanFailure` (no plan, and why), and `PlanFunction`, the
planner signature a request is answered with.

Apart from the service because these are the values passed between the controller and the
planner, in one process or across two: they hold no planning machinery, and a controller that
only asks and reads needs no more of the service than them and its `PlanService` protocol.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.motion.plan import Plan
from hrc_drake.motion.poses import (
    pose_from_values,
    pose_values,
    quantize_joints,
    quantize_opening,
    quantize_pose,
)
from hrc_drake.tasks.tokens import UNDO

PlanFunction = Callable[..., Plan]
"""(configuration, task, last_token, layout) -> Plan: the Supervisor's planner signature. A
request with a measured pick, start or obstacle, or a held part, calls it with the keywords of
`PlanRequest.keywords` too (`instance`, `source_pose` as a RigidTransform, `q_start` as an array,
`obstacle` as a RigidTransform, `held`, `start_opening`), as `MotionPlanner.plan_task` takes
them; an ordinary request never does."""


@dataclass(frozen=True)
class PlanRequest:
    """What a task plan depends on: build it with `PlanRequest.of`.

    Attributes:
        configuration: the tokens in place before the task.
        task: the task token (`F1`, `undo`, ...).
        last_token: the task done last (`undo` takes its part back).
        layout: (instance, token) for each placed part, sorted, as the cell measured it; None:
            the robot's own routine (`default_layout`).
        instance: the part instance the task moves (None: the lowest-numbered free one);
            required with `source_pose`.
        source_pose: where that part lies, measured, not seated (it is not in `layout`):
            (x, y, z, qw, qx, qy, qz) in the world, translation then
            `RotationMatrix.ToQuaternion()`; None: its tray home.
        start: the 6 UR3 joint positions the plan starts from; None: the planner's `q_home`.
        obstacle: the world pose (7 values, as `source_pose`) of a temporary obstacle the cell
            measures (`hrc_drake.obstacle_models`); None: no obstacle.
        held: `instance` is in the gripper already, the arm at `start` (a re-target, or with
            `undo` a swap: the part goes back to its tray home).
        start_opening: the gripper's opening at `start` [m] (None: the pick's own opening). A
            plan that starts with the fingers by a part keeps it until the arm is clear of the
            cell: closing them there at once would close them on that part.
    """

    configuration: frozenset[str]
    task: str
    last_token: str | None = None
    layout: tuple[tuple[str, str], ...] | None = None
    instance: str | None = None
    source_pose: tuple[float, ...] | None = None
    start: tuple[float, ...] | None = None
    obstacle: tuple[float, ...] | None = None
    held: bool = False
    start_opening: float | None = None

    @staticmethod
    def of(
        configuration: Iterable[str],
        task: str,
        last_token: str | None = None,
        layout: Mapping[str, str] | None = None,
        *,
        instance: str | None = None,
        source_pose: Sequence[float] | RigidTransform | None = None,
        start: Sequence[float] | None = None,
        obstacle: Sequence[float] | RigidTransform | None = None,
        held: bool = False,
        start_opening: float | None = None,
    ) -> PlanRequest:
        """From the planner's arguments (`layout`: instance -> token, e.g. measured;
        `source_pose` and `obstacle`: 7 values or a RigidTransform, the latter empty for none;
        `start`: 6 joint positions; `held`: the instance is in the gripper at `start`;
        `start_opening`: the gripper's opening there, with `start` only).
        ValueError for a source pose without its instance, a held part without its instance
        and start, or values of the wrong count."""
        placed = None if layout is None else tuple(sorted(layout.items()))
        if source_pose is not None:
            if instance is None:
                raise ValueError(
                    f"task {task}: a source pose needs the part lying there (instance=)"
                )
            if isinstance(source_pose, RigidTransform):
                source_pose = pose_values(source_pose)
            source_pose = tuple(float(v) for v in source_pose)
            quantize_pose(source_pose)  # checks the values
        if start is not None:
            start = tuple(float(v) for v in np.asarray(start, dtype=float).ravel())
            quantize_joints(start)
        if held and (instance is None or start is None):
            raise ValueError(f"task {task}: a held part needs its instance and start")
        if start_opening is not None:
            # Home's opening is the plan's own; a held part's grip sets it.
            held_or_home = start is None or held
            start_opening = None if held_or_home else quantize_opening(start_opening)
        if isinstance(obstacle, RigidTransform):
            obstacle = pose_values(obstacle)
        if obstacle is not None and len(obstacle) == 0:
            obstacle = None
        if obstacle is not None:
            obstacle = tuple(float(v) for v in obstacle)
            quantize_pose(obstacle)  # checks the values
        return PlanRequest(
            frozenset(configuration),
            task,
            last_token,
            placed,
            instance,
            source_pose,
            start,
            obstacle,
            bool(held),
            start_opening,
        )

    def layout_map(self) -> dict[str, str] | None:
        """The layout as instance -> token (the planner's argument)."""
        return None if self.layout is None else dict(self.layout)

    def keywords(self) -> dict:
        """The planner's keyword arguments for a measured pick, start or obstacle (`instance`,
        `source_pose` and `obstacle` as RigidTransforms, `q_start` as an array); {} for an
        ordinary request."""
        if self._ordinary():
            return {}
        keywords = {
            "instance": self.instance,
            "source_pose": None if self.source_pose is None else pose_from_values(self.source_pose),
            "q_start": None if self.start is None else np.array(self.start),
        }
        if self.obstacle is not None:
            keywords["obstacle"] = pose_from_values(self.obstacle)
        if self.held:
            keywords["held"] = True
        if self.start_opening is not None:
            keywords["start_opening"] = self.start_opening
        return keywords

    def _ordinary(self) -> bool:
        return (
            self.instance is None
            and self.source_pose is None
            and self.start is None
            and self.obstacle is None
            and not self.held
        )

    def key(self) -> tuple:
        """Requests with equal keys get the same plan: with a measured layout, the last task
        matters only to `undo` (as in `MotionPlanner`'s own cache key); a measured pose and
        start count to 0.1 mm and 1e-4 (`poses.KEY_DIGITS`), as the planner rounds them."""
        last = self.last_token if self.layout is None or self.task == UNDO else None
        key = (self.configuration, self.task, last, self.layout)
        if self._ordinary():
            return key
        source = None if self.source_pose is None else quantize_pose(self.source_pose)
        start = None if self.start is None else quantize_joints(self.start)
        obstacle = None if self.obstacle is None else quantize_pose(self.obstacle)
        return (*key, self.instance, source, start, obstacle, self.held, self.start_opening)


@dataclass(frozen=True)
class PlanFailure:
    """No plan for a request: `kind` is the error's class (UnreachableError, PlanningError,
    ValueError, ...), `reason` its message (it names the task, the pose and the constraint)."""

    request: PlanRequest
    kind: str
    reason: str

    @property
    def task(self) -> str:
        """The task that has no plan."""
        return self.request.task

    def __str__(self) -> str:
        request = self.request
        if request.held and request.task == UNDO:
            # A swap's return: the part in the gripper goes back to its tray, not an undo of
            # the last task (which, from an empty base, there is none).
            what = f"putting {request.instance} back in its tray"
        else:
            what = request.task
        return f"no plan for {what} from {sorted(request.configuration)}: {self.reason}"
