"""Cost tables from the motion layer: plan every task edge, add the operator's bolting time, and
plan the re-target and swap of every bet.

`compute_cost_table(space)` plans each (state, task) edge of the state graph with a
`MotionPlanner` whose bolting holds are zero, so that a plan's duration is the robot's time
only (home, pick, carry, place, release, retreat, home); the operator's part is the spec's
bolting time of the part placed (or unbolting time of the part undone, taken equal; see
`hrc_drake.tasks.costs`). A placement's carry milestones are its plan's: the lift done, the
pre-place pose reached. Each bet (a placement committed to, another task indicated) is planned
with the same planner (`bet_seconds`): a re-target as a collision-free carry from the committed
seat's pre-place posture to the indicated one's, a swap as the part put back (the lift run
backwards, the gripper opened, up again) and a free path from its pre-grasp to the indicated
task's. `cell_hash(planner)` names the cell a table was planned in, and
`default_cost_table(space)` computes the table once per (spec, cell) and caches it under the
user's cache folder. `hrc-drake costs --out FILE` is `hrc_drake.cli.costs`.

Only what a run can take is planned (`run_edges`, `bet_pairs`). An edge the motion layer cannot
plan is the operator's (`operator_edge`: the scenario's ``run.handover_time`` plus the bolting,
and the planner's reason), as the Supervisor hands it over at run time; a bet whose indicated
task is the operator's, or whose own motion cannot be planned, is priced without that motion
(`unplanned_bet_seconds`). Nothing the robot cannot plan refuses a spec.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion import MotionOptions, MotionPlanner, Plan, PlanningError, UnreachableError
from hrc_drake.motion.plan import LIFT
from hrc_drake.motion.reach_check import check_reach
from hrc_drake.motion.scene import Layout
from hrc_drake.motion.task_move import resolve_task
from hrc_drake.motion.trajectory import free_path, retime
from hrc_drake.resources import models_dir
from hrc_drake.scenario.schema import RunConfig
from hrc_drake.tasks.bets import Bet, bet_kind
from hrc_drake.tasks.costs import (
    BetKey,
    CostTable,
    CostTableError,
    Edge,
    EdgeCost,
    bet_pairs,
    load_cost_table,
    operator_edge,
    operator_seconds,
    run_edges,
    save_cost_table,
)
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

# The robot's model files: what the arm and gripper are (the cell's plate, tray and parts are
# generated from the spec's layout and enter the hash through the frames and the layout).
ROBOT_FILES = ("ur3/ur3.urdf", "rg2/rg2.sdf", "cell/robot.dmd.yaml")
Progress = Callable[[int, int, float], None]  # (edges done, edges, last plan's seconds)
# The seconds a task handed over takes by hand before its bolting: the scenario's default.
HANDOVER_TIME = RunConfig().handover_time
# What the motion layer raises for a task it cannot plan (no IK, a collision, the solver).
NO_PLAN = (PlanningError, UnreachableError, RuntimeError, ValueError)


def timing_options(options: MotionOptions | None = None) -> MotionOptions:
    """`options` (default MotionOptions()) with no bolting holds: plans take robot time only."""
    return dataclasses.replace(options or MotionOptions(), hold_time=0.0, undo_hold_time=0.0)


def timing_planner(space: StateSpace, options: MotionOptions | None = None) -> MotionPlanner:
    """A planner for `space`'s cell (the spec's layout) with `timing_options`."""
    return MotionPlanner(options=timing_options(options), design=CellDesign.of(space.spec))


def _pose(X) -> list[float]:
    # Rounded to 1 µm / 1 µrad so that the hash does not depend on the last bits of parsing.
    return [round(float(v), 6) + 0.0 for v in X.GetAsMatrix4()[:3].ravel()]


def cell_hash(planner: MotionPlanner) -> str:
    """A hash of what a planned duration depends on: the motion options, the planner's frames
    (seats, tray homes, grasps, host rows, grip widths, home posture; rounded) and the text of
    the robot's model files."""
    frames = planner.frames
    content = {
        "options": dataclasses.asdict(planner.options),
        "seats": {str(k): _pose(X) for k, X in sorted(frames.seats.items())},
        "homes": {k: _pose(X) for k, X in sorted(frames.homes.items())},
        "grasps": {k: _pose(X) for k, X in sorted(frames.grasps.items())},
        "rows": {
            str(h): {str(j): _pose(X) for j, X in sorted(rows.items())}
            for h, rows in sorted(frames.rows.items())
        },
        "widths": {k: round(float(w), 6) for k, w in sorted(frames.widths.items())},
        "tray": _pose(frames.tray),
        "q_home": [round(float(q), 6) + 0.0 for q in planner.q_home],
        "layout": repr(frames.design.layout.key()),
        "robot": {
            name: hashlib.sha256((models_dir() / name).read_bytes()).hexdigest()
            for name in ROBOT_FILES
        },
    }
    text = json.dumps(content, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plan_edge(
    planner: MotionPlanner, space: StateSpace, state: tuple[str, ...], task: str
) -> Plan:
    """The one call into the motion layer: the plan of `task` from `state` (home to home)."""
    configuration = space.configuration(space.index(state))
    return planner.plan_task(configuration, task, last_token=state[-1] if state else None)


def _robot_seconds(planner: MotionPlanner, plan: Plan, task: str) -> float:
    # Holds are zero with `timing_options`; with another planner, take them out.
    hold = planner.options.undo_hold_time if task == UNDO else planner.options.hold_time
    return float(plan.duration) - hold


def _motion(plan: Plan, name: str):
    """The arm motion `name` of a plan (`MotionPlanner` names them)."""
    return next(m for m in plan.motions if m.name == name)


def carry_milestones(plan: Plan) -> tuple[float, float]:
    """(carry_start, carry_end) of a placement's plan: when the part is lifted out of the tray,
    and when it reaches the pre-place pose above its seat [s from the start]."""
    carry = _motion(plan, "carry to pre-place")
    return round(carry.start, 4), round(carry.start + carry.duration, 4)


def _free_seconds(planner: MotionPlanner, layout: Layout, q_start, q_end) -> float:
    """Seconds of a collision-free path between two postures at rest in `layout`, retimed as
    the planner's own free motions are."""
    scene = planner.scene(layout)
    scene.set_allowed_contacts(())
    path, _ = free_path(scene, q_start, q_end, planner.limits, planner.options)
    return retime(scene, path, planner.limits, planner.options).duration


def bet_seconds(
    planner: MotionPlanner,
    space: StateSpace,
    state: tuple[str, ...],
    committed: str,
    indicated: str,
) -> float:
    """The planned seconds a bet adds at most (`hrc_drake.tasks.costs`): a re-target carries the
    part from the committed seat's pre-place posture to the indicated one's (against carrying it
    there directly); a swap puts the part back in its tray home and goes from its pre-grasp to
    the indicated task's (against going there from home)."""
    a = _plan_edge(planner, space, state, committed)
    b = _plan_edge(planner, space, state, indicated)
    configuration = space.configuration(space.index(state))
    last = state[-1] if state else None
    if bet_kind(space, committed, indicated) == Bet.RETARGET:
        move = resolve_task(planner.frames, configuration, committed, last)
        carry = Layout.of(move.before, move.instance, planner.frames.widths[move.instance])
        (_, end_a), (_, end_b) = carry_milestones(a), carry_milestones(b)
        between = _free_seconds(planner, carry, a.positions(end_a), b.positions(end_b))
        return round(max(0.0, end_a + between - end_b), 4)
    move = resolve_task(planner.frames, configuration, indicated, last)
    opening = max(a.gripper_opening(0.0), b.gripper_opening(0.0))
    pregrasp_a, pregrasp_b = _motion(a, "home to pre-grasp"), _motion(b, "home to pre-grasp")
    at_a = pregrasp_a.start + pregrasp_a.duration
    at_b = pregrasp_b.start + pregrasp_b.duration
    empty = Layout.of(move.before, None, opening)
    between = _free_seconds(planner, empty, a.positions(at_a), b.positions(at_b))
    return round(max(0.0, carry_milestones(a)[0] + _put_back(planner, a) + between - at_b), 4)


def _put_back(planner: MotionPlanner, plan: Plan) -> float:
    """Seconds to put a lifted part back where it was picked: lowered (the lift run backwards),
    released, up again."""
    return 2.0 * _motion(plan, LIFT).duration + planner.options.gripper_time


def unplanned_bet_seconds(
    planner: MotionPlanner, space: StateSpace, state: tuple[str, ...], committed: str, kind: Bet
) -> float:
    """The seconds of a bet priced without a motion the robot cannot plan (its indicated task,
    or the move between the two): the committed part is put back in its tray home, from its
    lift (a swap: `kind` SWAP; the interaction model adds the way back along the carry) or from
    above the committed seat (a re-target: the carry back and the put-back), and the indicated
    task then starts as from home (or is handed over)."""
    a = _plan_edge(planner, space, state, committed)
    start, end = carry_milestones(a)
    back = start + _put_back(planner, a)
    return round(back if kind == Bet.SWAP else back + 2.0 * (end - start), 4)


def _edge_cost(
    planner: MotionPlanner, space: StateSpace, state, task: str, handover: float
) -> EdgeCost:
    """The cost of an edge: the robot's plan plus the bolting, or, when the robot cannot plan
    it, the operator's by hand (`operator_edge`, with the planner's reason)."""
    operator = operator_seconds(space.spec, tuple(state), task)
    try:
        plan = _plan_edge(planner, space, tuple(state), task)
    except NO_PLAN as err:
        return operator_edge(handover, operator, str(err))
    robot = round(_robot_seconds(planner, plan, task), 4)
    start, end = (None, None) if task == UNDO else carry_milestones(plan)
    return EdgeCost(round(robot + operator, 4), robot, operator, start, end)


def compute_cost_table(
    space: StateSpace,
    planner: MotionPlanner | None = None,
    progress: Progress | None = None,
    edges: Iterable[Edge] | None = None,
    handover_time: float = HANDOVER_TIME,
) -> CostTable:
    """Plan every edge a run of `space` can take (`run_edges`) and every bet (`bet_pairs`), and
    return the cost table; with `edges`, only those edges and no bets.

    Seconds = robot time (the plan's duration without bolting holds) + the operator's
    (un)bolting time from the spec. An edge the robot cannot plan is the operator's:
    `handover_time` seconds by hand (the scenario's ``run.handover_time``) plus the bolting,
    with the planner's reason. A bet on it is left out (the robot never starts on it); a bet
    whose indicated task is the operator's, or whose own motion fails, is priced as
    `unplanned_bet_seconds`. First the reach check (`check_reach`): CellModelError naming the
    part or slot the UR3 cannot reach and a layout that it can, the same error `simulate` gives.
    """
    planner = planner or timing_planner(space)
    check_reach(planner)
    todo = list(run_edges(space) if edges is None else edges)
    pairs: list[BetKey] = bet_pairs(space) if edges is None else []
    total = len(todo) + len(pairs)
    entries: dict[Edge, EdgeCost] = {}
    for i, (state, task) in enumerate(todo):
        entries[tuple(state), task] = cost = _edge_cost(planner, space, state, task, handover_time)
        if progress:
            progress(i + 1, total, cost.seconds)
    bets: dict[BetKey, float] = {}
    for i, (state, committed, indicated) in enumerate(pairs):
        if entries[state, committed].by_operator:
            continue  # the robot never starts on a task it cannot plan (`bet_pairs`)
        kind = bet_kind(space, committed, indicated)
        if entries[state, indicated].by_operator:
            seconds = unplanned_bet_seconds(planner, space, state, committed, Bet.SWAP)
        else:
            try:
                seconds = bet_seconds(planner, space, state, committed, indicated)
            except NO_PLAN:
                seconds = unplanned_bet_seconds(planner, space, state, committed, kind)
        bets[state, committed, indicated] = seconds
        if progress:
            progress(len(todo) + i + 1, total, seconds)
    return CostTable(
        space.spec.spec_hash,
        cell_hash(planner),
        entries,
        space.spec.name,
        bets=bets if edges is None else None,
    )


def cache_dir() -> Path:
    """Where cached cost tables live: $XDG_CACHE_HOME/hrc_drake, else ~/.cache/hrc_drake."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hrc_drake"


def default_cost_table(
    space: StateSpace,
    planner: MotionPlanner | None = None,
    progress: Progress | None = None,
    folder: Path | None = None,
) -> CostTable:
    """The cost table of `space` in its cell, computed once and cached; its operator's edges
    are priced at the default `HANDOVER_TIME` (a scenario's own: `CostTable.with_handover_time`).

    The file is ``costs-<spechash>-<cellhash>.json`` under `folder` (default `cache_dir()`),
    written atomically; an unreadable cached file is recomputed and replaced.
    """
    planner = planner or timing_planner(space)
    path = (folder or cache_dir()) / f"costs-{space.spec.spec_hash}-{cell_hash(planner)}.json"
    if path.is_file():
        try:
            return load_cost_table(path, space, cell_hash=cell_hash(planner))
        except CostTableError as err:
            print(f"cost table cache: {err}; recomputing", file=sys.stderr)
    table = compute_cost_table(space, planner, progress)
    save_cost_table(table, path)
    return table


__all__ = [
    "HANDOVER_TIME",
    "cache_dir",
    "cell_hash",
    "compute_cost_table",
    "default_cost_table",
    "timing_options",
    "timing_planner",
    "unplanned_bet_seconds",
]
