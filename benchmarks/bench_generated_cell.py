"""The cell generated from an assembly spec: 3, 4 and 5 slots side by side, and every edge of
the 4-slot graph planned.

Run on demand (not part of pytest):

    python benchmarks/bench_generated_cell.py [--skip-edges] [--assemblies flange,four-slot]
        [--lean] [--out report.md]

1. For the flange case (3 slots), `four-slot` and `five-slot` (the same rules on wider bases):
   `make_cell_station` time (best of 3), the reach check's time, and a full-settings closed-loop
   run (5 s bolting holds, 0.25 m/s TCP; `--lean`: 0.5 s holds, a smoke run) of the robot's own
   route: simulated assembly time and real-time factor including planning (in the run's planning
   worker, cold), then the same run again with every plan cached.
2. Every edge (state, task) of the 4-slot graph — placements and undos — planned from the
   layout the robot's own routine gives, and validated at 100 Hz: success and planning time.
Writes benchmarks/reports/generated_cell.md (atomically; or `--out`).
"""

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario, motion_options
from hrc_drake.cell.station import make_cell_station
from hrc_drake.cell_models import CellDesign
from hrc_drake.motion import MotionPlanner, check_plan
from hrc_drake.motion.reach_check import check_reach
from hrc_drake.resources import models_dir
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

REPORT = Path(__file__).resolve().parent / "reports" / "generated_cell.md"
ASSEMBLIES = ("flange", "four-slot", "five-slot")


def _cell_rows(assemblies: list[str], lean: bool) -> list[str]:
    rows = []
    for name in assemblies:
        spec_path = models_dir() / "assemblies" / f"{name}.yaml"
        design = CellDesign.of(load_spec(spec_path))
        builds = []
        for _ in range(3):
            t0 = time.perf_counter()
            make_cell_station(dataclasses.replace(Scenario(), assembly=str(spec_path)))
            builds.append(time.perf_counter() - t0)
        texts = [f"{{assembly: {spec_path}, name: {name}}}", *([LEAN] if lean else [])]
        scenario = load_cell_scenario(None, texts)
        t0 = time.perf_counter()
        planner = MotionPlanner(motion_options(scenario), design=design)
        check_reach(planner)
        reach = time.perf_counter() - t0
        print(f"{name}: full run (planning) ...", flush=True)
        first = run_scenario(scenario)  # the run's planning worker starts cold
        print(f"{name}: full run (plans cached) ...", flush=True)
        again = run_scenario(scenario)
        ok = first.done and again.done and not first.collisions and not again.collisions
        rows.append(
            f"| {name} | {design.slots} | {' '.join(' '.join(s[-1:]) for s in first.states[1:])} "
            f"| {'yes' if ok else 'NO'} | {min(builds):.2f} | {reach:.2f} | "
            f"{first.sim_time:.1f} | {first.real_time_factor:.2f} | "
            f"{again.real_time_factor:.2f} |"
        )
    return rows


def _edge_rows() -> tuple[list[str], list[str]]:
    spec = load_spec(models_dir() / "assemblies" / "four-slot.yaml")
    space = generate_states(spec)
    planner = MotionPlanner(design=CellDesign.of(spec))
    times, failures, count = [], [], 0
    for s in range(space.n_states):
        state = space.sequence(s)
        for task, _ in space.tasks(s):
            count += 1
            t0 = time.perf_counter()
            try:
                plan = planner.plan_task(
                    space.configuration(s), task, last_token=state[-1] if state else None
                )
                report = check_plan(plan, planner)
                if not report.ok:
                    failures.append(f"{' '.join(state)} + {task}: {report.problems[0]}")
            except (RuntimeError, ValueError) as err:
                failures.append(f"{' '.join(state) or '(start)'} + {task}: {err}")
            times.append(time.perf_counter() - t0)
            print(f"\redges {count}", end="", flush=True)
    print()
    undos = sum(1 for s in range(space.n_states) for t, _ in space.tasks(s) if t == UNDO)
    summary = [
        f"{count} edges ({count - undos} placements, {undos} undos) of the {space.n_states}-"
        f"state graph; planned and valid: **{count - len(failures)}/{count}**.",
        "",
        f"Planning + validation time per edge (plans cached by layout, so repeated layouts "
        f"are free): median {statistics.median(times):.2f} s, max {max(times):.2f} s, "
        f"total {sum(times):.0f} s.",
    ]
    return summary, failures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--skip-edges", action="store_true")
    parser.add_argument("--assemblies", default=",".join(ASSEMBLIES), help="comma-separated")
    parser.add_argument("--lean", action="store_true", help="0.5 s holds (a smoke run)")
    parser.add_argument("--out", type=Path, default=REPORT)
    argv = sys.argv[1:]
    args = parser.parse_args(argv)
    settings = (
        "lean settings (5 ms SAP, 0.5 s bolting holds"
        if args.lean
        else "full settings (5 ms SAP, 5 s bolting holds"
    )
    lines = [
        "# Generated cells",
        "",
        f"Command: `python benchmarks/bench_generated_cell.py{''.join(' ' + a for a in argv)}`. "
        "The cell (plate, tray, parts) is "
        f"generated from each assembly spec; {settings}, TCP <= 0.25 m/s), the operator's body "
        "and separation monitoring on (the defaults); the operator follows the robot; the plans "
        "come from the run's planning worker (a process beside the controller).",
        "",
        "| assembly | slots | route | terminal, 0 collisions | build [s] | reach check [s] | "
        "simulated [s] | RTF incl. planning | RTF plans cached |",
        "|---|---|---|---|---|---|---|---|---|",
        *_cell_rows(args.assemblies.split(","), args.lean),
        "",
    ]
    if not args.skip_edges:
        summary, failures = _edge_rows()
        lines += ["## Every edge of the 4-slot graph", "", *summary, ""]
        lines += [f"- {f}" for f in failures] or ["No failures."]
        lines.append("")
    atomic_write_text(args.out, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
