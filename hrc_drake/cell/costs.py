"""Cost tables from the motion layer: plan every task edge, add the operator's bolting time.

`compute_cost_table(space)` plans each (state, task) edge of the state graph with a
`MotionPlanner` whose bolting holds are zero, so that a plan's duration is the robot's time
only (home, pick, carry, place, release, retreat, home); the operator's part is the spec's
bolting time of the part placed (or unbolting time of the part undone, taken equal; see
`hrc_drake.tasks.costs`). `cell_hash(planner)` names the cell a table was planned in, and
`default_cost_table(space)` computes the table once per (spec, cell) and caches it under the
user's cache folder. `hrc-drake costs --out FILE` is `costs_command`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from hrc_drake.cell_models import CellDesign
from hrc_drake.motion import MotionOptions, MotionPlanner, Plan, PlanningError, UnreachableError
from hrc_drake.motion.planner import check_reach
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import (
    CostTable,
    CostTableError,
    Edge,
    EdgeCost,
    cost_summary,
    load_cost_table,
    operator_seconds,
    save_cost_table,
    task_edges,
)
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.mdp import MdpConfig
from hrc_drake.tasks.tokens import UNDO

# The robot's model files: what the arm and gripper are (the cell's plate, tray and parts are
# generated from the spec's layout and enter the hash through the frames and the layout).
ROBOT_FILES = ("ur3/ur3.urdf", "rg2/rg2.sdf", "cell/robot.dmd.yaml")
Progress = Callable[[int, int, float], None]  # (edges done, edges, last plan's seconds)


class CostPlanningError(RuntimeError):
    """A task edge the motion layer could not plan, so no complete cost table."""


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


def compute_cost_table(
    space: StateSpace,
    planner: MotionPlanner | None = None,
    progress: Progress | None = None,
    edges: Iterable[Edge] | None = None,
) -> CostTable:
    """Plan every task edge of `space` (or only `edges`) and return the cost table.

    Seconds = robot time (the plan's duration without bolting holds) + the operator's
    (un)bolting time from the spec. First the reach check (`check_reach`): CellModelError naming
    the part or slot the UR3 cannot reach and a layout that it can, the same error `simulate`
    gives. CostPlanningError naming the edge if one cannot be planned.
    """
    planner = planner or timing_planner(space)
    check_reach(planner)
    todo = list(task_edges(space) if edges is None else edges)
    entries: dict[Edge, EdgeCost] = {}
    for i, (state, task) in enumerate(todo):
        try:
            plan = _plan_edge(planner, space, tuple(state), task)
        except (PlanningError, UnreachableError, RuntimeError, ValueError) as err:
            raise CostPlanningError(
                f"cannot plan task {task!r} from state {list(state)}: {err}; a cost table needs "
                "every task edge (check the cell layout or the motion options)"
            ) from err
        robot = round(_robot_seconds(planner, plan, task), 4)
        operator = operator_seconds(space.spec, tuple(state), task)
        entries[tuple(state), task] = EdgeCost(round(robot + operator, 4), robot, operator)
        if progress:
            progress(i + 1, len(todo), robot + operator)
    return CostTable(space.spec.spec_hash, cell_hash(planner), entries, space.spec.name)


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
    """The cost table of `space` in its cell, computed once and cached.

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


def costs_command(args) -> int:
    """`hrc-drake costs --out FILE [--json]`: plan every edge, save the table, rank sequences.
    A layout the UR3 cannot reach, or an edge that cannot be planned, is a one-line UsageError."""
    from hrc_drake.cell_models import CellModelError
    from hrc_drake.paths import UsageError, check_output_path
    from hrc_drake.progress import ProgressLine
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    check_output_path(args.out, "--out")
    space = generate_states(load_spec(args.assembly))
    start = time.perf_counter()
    try:
        planner = timing_planner(space)
        with ProgressLine("planning task edges", "edge") as bar:
            table = compute_cost_table(space, planner, progress=bar.update)
    except (CellModelError, CostPlanningError) as err:
        raise UsageError(str(err)) from None
    wall = time.perf_counter() - start
    save_cost_table(table, args.out)
    config = MdpConfig(
        gamma=1.0 if args.gamma is None else args.gamma, mistake_prob=args.mistake_prob
    )
    summary = {
        "out": str(args.out),
        **cost_summary(space, table, config),
        "wall_time": round(wall, 2),
    }
    if args.json:
        json.dump(summary, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    print(
        f"{summary['edges']} task edges of {space.spec.name!r} planned in {wall:.1f} s "
        f"(cell {table.cell_hash}) -> {args.out}"
    )
    print(
        "shortest sequences, fastest first (as proposed; expected with the operator's "
        f"{summary['mistake_prob']:.0%} mistakes):"
    )
    for r in summary["shortest_sequences"]:
        parts = " + ".join(f"{t:.2f}" for t in r["task_seconds"])
        print(
            f"  {r['states']:<12} {' '.join(r['tasks']):<14} {r['seconds']:7.2f} s  "
            f"({parts})  expected {r['expected_seconds']:.3f} s"
        )
    for key, label in (("time_aware_choice", "time-aware"), ("unit_cost_choice", "unit-cost")):
        c = summary[key]
        print(
            f"{label} choice: {c['states']} ({' '.join(c['tasks'])}), {c['seconds']:.2f} s, "
            f"expected {c['expected_seconds']:.3f} s"
        )
    return 0


__all__ = [
    "CostPlanningError",
    "cache_dir",
    "cell_hash",
    "compute_cost_table",
    "costs_command",
    "default_cost_table",
    "timing_options",
    "timing_planner",
]
