"""What a plan is of: the part a task moves from where to where, and the measured inputs of a
re-plan rounded to the plan cache's resolution, which together make the plan cache's key.

Apart from the planner because it is bookkeeping over the spec and the cell's frames, decided
before any IK or path: which instance sits at each token, which one moves, and which of the
measured values (a part's pose, the arm's posture, an obstacle) the plan depends on.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.motion.poses import (
    CellFrames,
    default_layout,
    pose_values,
    quantize_joints,
    quantize_opening,
    quantize_pose,
)
from hrc_drake.tasks.tokens import UNDO


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
class Measured:
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
class MeasuredKeywords:
    """`MotionPlanner.plan_task`'s measured keywords as given (before rounding)."""

    instance: str | None = None
    source_pose: RigidTransform | None = None
    q_start: np.ndarray | None = None
    obstacle: RigidTransform | None = None
    held: bool = False
    start_opening: float | None = None


def resolve_request(
    frames: CellFrames,
    configuration: frozenset[str],
    task: str,
    last_token: str | None,
    layout: Mapping[str, str] | None,
    given: MeasuredKeywords,
    joints: int,
) -> tuple[TaskMove, Measured]:
    """`plan_task`'s arguments as the move and its rounded measured inputs (`joints`: how many
    joint positions a start posture has)."""
    instance, source_pose, q_start, obstacle = (
        given.instance,
        given.source_pose,
        given.q_start,
        given.obstacle,
    )
    if given.held:
        move = _held_move(frames, configuration, task, last_token, layout, given)
    elif source_pose is not None and task == UNDO:
        raise ValueError(
            "undo takes the part placed last from its seat; a source pose is for assembly "
            "tasks (plan the part's placement from where it lies instead)"
        )
    elif source_pose is not None and instance is None:
        raise ValueError(f"task {task}: a source pose needs the part lying there (instance=)")
    else:
        move = resolve_task(frames, configuration, task, last_token, layout, instance)
    measured = Measured(
        instance,
        None if source_pose is None else quantize_pose(pose_values(source_pose)),
        None if q_start is None else quantize_joints(q_start, joints),
        () if obstacle is None else quantize_pose(pose_values(obstacle)),
        given.held,
        None
        if given.start_opening is None or q_start is None or given.held
        else quantize_opening(given.start_opening),
    )
    return move, measured


def _held_move(
    frames: CellFrames,
    configuration: frozenset[str],
    task: str,
    last_token: str | None,
    layout: Mapping[str, str] | None,
    given: MeasuredKeywords,
) -> TaskMove:
    """The move of a part already in the gripper: to `task`'s seat, or (`undo`) home."""
    if given.instance is None or given.q_start is None:
        raise ValueError(f"task {task}: a held part needs its instance and q_start")
    if given.source_pose is not None:
        raise ValueError(f"task {task}: a held part is in the gripper, not lying somewhere")
    if task != UNDO:
        return resolve_task(frames, configuration, task, last_token, layout, given.instance)
    if layout is None:
        layout = default_layout(frames, configuration, last_token)
    before = {token: inst for inst, token in layout.items()}
    if given.instance in before.values():
        raise ValueError(f"{given.instance} is placed in the layout, not held")
    return TaskMove(UNDO, given.instance, None, None, before, before)


def plan_key(move: TaskMove, measured: Measured) -> tuple:
    """The plan cache's key of a move and its measured inputs."""
    # Which part sits where, and which one moves: all a plan depends on; and, when given,
    # the part named, where it lies and the posture the arm starts from.
    key = (move.task, frozenset(move.before.items()), move.source)
    if measured == Measured():
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
