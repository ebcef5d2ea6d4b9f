"""The occupancy rule against exhaustive planning: every task edge of small specs, at several
slot pitches, planned by the motion layer and judged by the rule.

Run on demand (not part of pytest):

    python benchmarks/bench_occupancy.py [--cases flange@0.08,four-slot@0.07,...] [--out FILE]

For each case, a spec (a name under models/assemblies/, or a path) at a slot pitch (the spec's
layout with only `slot_pitch` changed; default: `CASES`, the pitches where each spec's closest
neighbours have 15 mm down to nothing between them): every edge (state, task) of the state
graph — placements and undos, from the layout the robot's own routine gives — is planned with
`MotionPlanner.plan_task` and validated at 100 Hz (`check_plan`), and judged by the occupancy
rule on that edge (`hrc_drake.motion.occupancy.edge_room`). A rule that agrees passes exactly
the edges that plan. Also the spec-level verdict the reach check gives before a run
(`check_occupancy`: no breach over every move the spec allows) against "every edge planned",
and the time of each. Writes benchmarks/reports/occupancy.md (atomically; or `--out`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections import Counter
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.layout import layout_from
from hrc_drake.motion import MotionPlanner, check_plan
from hrc_drake.motion.occupancy import check_occupancy, edge_room, host_placements
from hrc_drake.motion.reach_check import cell_geometry, check_grasps
from hrc_drake.motion.task_move import resolve_task
from hrc_drake.resources import models_dir
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

HERE = Path(__file__).resolve().parent
REPORT = HERE / "reports" / "occupancy.md"
TWO_HOSTS = str(HERE / "specs" / "two-hosts.yaml")
# An oval flange is 65 mm long, a two-row host pitch + 70 mm: at 80, 75, 70 and 65 mm two oval
# flanges side by side have 15, 10, 5 and 0 mm between them, an oval flange beside a host 12.5,
# 7.5, 2.5 and 0, two hosts 10, 5, 0 and 0. (The 4-slot graph at 80 mm: 86/86 edges plan,
# benchmarks/reports/generated_cell.md.)
CASES = (
    *(f"flange@{p}" for p in (0.08, 0.075, 0.07, 0.065)),
    "four-slot@0.075",
    "four-slot@0.07",
    *(f"{TWO_HOSTS}@{p}" for p in (0.08, 0.075, 0.07)),
    "five-slot@0.07",
)


def _spec_path(name: str) -> Path:
    path = Path(name)
    return path if path.suffix == ".yaml" else models_dir() / "assemblies" / f"{name}.yaml"


def _short(err: Exception) -> str:
    text = str(err).split(" — ")[-1] if " — " in str(err) else str(err)
    return text[:110]


def _plans(planner: MotionPlanner, configuration, task: str, last, **given) -> tuple[bool, str]:
    """Whether the motion layer plans the edge and the plan validates; and why not."""
    try:
        plan = planner.plan_task(configuration, task, last_token=last, **given)
        report = check_plan(plan, planner)
        return report.ok, "" if report.ok else report.problems[0]
    except (RuntimeError, ValueError) as err:
        return False, _short(err)


def _plans_alone(planner: MotionPlanner, configuration, task: str, last) -> bool:
    """Whether the edge plans with no neighbour in place: only what its part rests on (and for
    undo the part itself), the same part instances where they were."""
    frames = planner.frames
    move = resolve_task(frames, configuration, task, last)
    seat = move.source if task == UNDO else move.target
    keep = (set(host_placements(frames.spec, seat)) & set(configuration)) | (
        {seat} if task == UNDO else set()
    )
    layout = {i: t for t, i in move.before.items() if t in keep}
    given = {} if task == UNDO else {"instance": move.instance}
    bare_last = last if task == UNDO else next(iter(keep), None)
    ok, _ = _plans(planner, frozenset(keep), task, bare_last, layout=layout, **given)
    return ok


def _one(spec_path: Path, pitch: float) -> dict:
    """Plan and judge every edge of one spec at one pitch; an edge the rule passes and the
    planner does not is planned again with no neighbour in place, to tell a neighbour the rule
    missed from a failure of reach or of the planner's own."""
    spec = load_spec(spec_path)
    layout = dataclasses.replace(layout_from(spec.cell), slot_pitch=pitch)
    design = CellDesign.of(spec, layout)
    space = generate_states(spec)
    try:
        planner = MotionPlanner(design=design)
    except CellModelError as err:  # not even the home pose above the work
        return {"error": str(err)}
    try:
        check_grasps(planner, suggest=False)
        reach = ""
    except CellModelError as err:
        reach = str(err)
    t0 = time.perf_counter()
    geometry = cell_geometry(planner)
    breaches = check_occupancy(geometry)
    check_time = time.perf_counter() - t0
    matrix: Counter = Counter()
    disagree, failures = [], Counter()
    missed = 0  # rule passes, planning fails, and plans with no neighbour in place
    rule_time = plan_time = 0.0
    for s in range(space.n_states):
        state = space.sequence(s)
        configuration = space.configuration(s)
        last = state[-1] if state else None
        for task, _ in space.tasks(s):
            t0 = time.perf_counter()
            crowded = edge_room(geometry, configuration, task, last)
            rule_time += time.perf_counter() - t0
            t0 = time.perf_counter()
            planned, why = _plans(planner, configuration, task, last)
            plan_time += time.perf_counter() - t0
            passes = crowded is None
            matrix[(passes, planned)] += 1
            if not planned:
                failures[why] += 1
            if passes != planned:
                edge = f"{' '.join(state) or '(start)'} + {task}"
                rule = "passes" if passes else crowded.describe(spec)
                alone = ""
                if passes:
                    ok = _plans_alone(planner, configuration, task, last)
                    missed += ok
                    alone = "; with no neighbour " + ("it plans" if ok else "it fails too")
                disagree.append(f"{edge}: rule {rule}; planning {'ok' if planned else why}{alone}")
            if sum(matrix.values()) % 25 == 0:
                print(f"{spec.name} {pitch}: {sum(matrix.values())} edges", file=sys.stderr)
    return {
        "states": space.n_states,
        "matrix": matrix,
        "missed": missed,
        "disagree": disagree,
        "failures": failures,
        "reach": reach,
        "check": not breaches,
        "first": breaches[0].describe(spec) if breaches else "",
        "check_time": check_time,
        "rule_time": rule_time,
        "plan_time": plan_time,
    }


def _row(label: str, r: dict) -> tuple[str, list[str]]:
    """One case's table row and its notes (planning failures, the check's first breach, the
    disagreements)."""
    if "error" in r:
        return f"| {label} | {r['error'][:100]} |" + " |" * 12, []
    m = r["matrix"]
    edges = sum(m.values())
    planned = m[(True, True)] + m[(False, True)]
    row = (
        f"| {label} | {r['states']} | {'refuse' if r['reach'] else 'pass'} | "
        f"{'pass' if r['check'] else 'refuse'} | {edges} | {planned} | {m[(True, True)]} | "
        f"{m[(False, False)]} | {m[(True, False)]} ({r['missed']}) | {m[(False, True)]} | "
        f"{r['check_time']:.2f} | {1e3 * r['rule_time'] / edges:.1f} | "
        f"{r['plan_time'] / edges:.2f} |"
    )
    where = label.replace(" |", " at")
    notes = []
    if r["reach"]:
        notes.append(f"- {where}: the reach check refuses: {r['reach'][:160]}")
    if r["failures"]:
        causes = "; ".join(f"{n}× {w}" for w, n in r["failures"].most_common(3))
        notes.append(f"- {where}: planning failed: {causes}")
    if r["first"]:
        notes.append(f"- {where}: the room check refuses: {r['first']}")
    notes += [f"  - disagreement: {d}" for d in r["disagree"][:4]]
    if len(r["disagree"]) > 4:
        notes.append(f"  - and {len(r['disagree']) - 4} more disagreements")
    return row, notes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated SPEC@PITCH")
    parser.add_argument("--out", type=Path, default=REPORT)
    argv = sys.argv[1:]
    args = parser.parse_args(argv)
    rows, notes = [], []
    totals: Counter = Counter()
    for case in args.cases.split(","):
        name, _, pitch_text = case.rpartition("@")
        path, pitch = _spec_path(name), float(pitch_text)
        result = _one(path, pitch)
        row, more = _row(f"{path.stem} | {pitch:.3f}", result)
        rows.append(row)
        notes += more
        totals.update(result.get("matrix", {}))
        totals["missed"] += result.get("missed", 0)
        atomic_write_text(args.out, _report(argv, rows, notes, totals))
    print(_report(argv, rows, notes, totals))


def _report(argv: list[str], rows: list[str], notes: list[str], totals: Counter) -> str:
    """The report's text so far."""
    edges = sum(n for key, n in totals.items() if key != "missed")
    lines = [
        "# The occupancy rule against exhaustive planning",
        "",
        f"Command: `python benchmarks/bench_occupancy.py{''.join(' ' + a for a in argv)}`. Every "
        "edge (state, task) of each spec's graph, placements and undos, planned by the motion "
        "layer from the robot's own routine and validated at 100 Hz, and judged by the "
        "occupancy rule (`hrc_drake/motion/occupancy.py`, `edge_room`); the spec's layout with "
        "only `slot_pitch` changed.",
        "",
        f"Over all {edges} edges: rule passes and planning succeeds {totals[(True, True)]}, "
        f"rule refuses and planning fails {totals[(False, False)]}, rule passes but planning "
        f"fails {totals[(True, False)]} (**of which {totals['missed']} plan with no neighbour "
        f"in place**: a neighbour the rule missed), rule refuses but planning succeeds "
        f"{totals[(False, True)]}.",
        "",
        "The check before a run: the reach check (IK at every grasp in the empty cell, "
        "`check_grasps`) and the room check (the rule over every move the spec allows, "
        "`check_occupancy`). An edge the rule passes and the planner does not is planned again "
        "with no neighbour in place (only what its part rests on): if it fails again, the "
        "neighbours are not the cause (reach, or the planner's own failure).",
        "",
        "| spec | pitch [m] | states | reach check | room check | edges | planned | both pass "
        "| both refuse | rule passes, plan fails (plans alone) | rule refuses, plan ok "
        "| room check [s] | rule per edge [ms] | planning per edge [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        *notes,
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
