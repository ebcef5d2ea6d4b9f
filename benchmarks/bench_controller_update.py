"""The Supervisor's update never waits for the planner.

Runs a Table 2 row with simulated time running on while the planner works (`run:
wait_for_planner: false`, as on a real cell) against a planning worker with an empty cache, and
times every update of the Supervisor, sorting them by whether a plan was being computed at the
time. Side by side in the same run: the same row with the planner inside the update (an
in-process planner, as the controller planned before), where the update that asks for a plan
lasts as long as the planning.

    python benchmarks/bench_controller_update.py [--scenario row7-forces-9] [--lean]

Writes benchmarks/reports/controller_update.md. Target: the longest update while a plan is being
computed is under 5 ms.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from hrc_drake.cell.controller import supervisor as supervisor_module
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario, motion_options
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.service import WorkerPlanService
from hrc_drake.tasks.spec import load_spec

REPORT = Path(__file__).parent / "reports" / "controller_update.md"
FREE_RUNNING = "{run: {wait_for_planner: false}}"


class _Timer:
    """Wraps Supervisor._update: its wall duration, and whether the planner was busy."""

    def __init__(self):
        self.samples: list[tuple[float, bool]] = []
        self.busy = lambda: False
        self._original = supervisor_module.Supervisor._update

    def __enter__(self):
        timer = self

        def timed(supervisor, context, state):
            busy = timer.busy()
            start = time.perf_counter()
            timer._original(supervisor, context, state)
            timer.samples.append((time.perf_counter() - start, busy))

        supervisor_module.Supervisor._update = timed
        return self

    def __exit__(self, *exc):
        supervisor_module.Supervisor._update = self._original


def _in_flight(service: WorkerPlanService) -> bool:
    return service.pending() > 0


def _figures(samples: list[tuple[float, bool]], busy_only: bool) -> dict:
    values = np.array([d for d, busy in samples if busy or not busy_only]) * 1000
    if len(values) == 0:
        return {"n": 0, "median": float("nan"), "p99": float("nan"), "max": float("nan")}
    return {
        "n": len(values),
        "median": float(np.median(values)),
        "p99": float(np.percentile(values, 99)),
        "max": float(values.max()),
    }


def main() -> None:
    """Run both ways and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="row7-forces-9")
    parser.add_argument("--lean", action="store_true", help="0.5 s bolting holds")
    args = parser.parse_args()
    texts = [LEAN, FREE_RUNNING] if args.lean else [FREE_RUNNING]
    scenario = load_cell_scenario(args.scenario, texts)
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    options = motion_options(scenario)

    worker = WorkerPlanService(options, design)  # an empty plan cache: every plan is computed
    with _Timer() as beside:
        beside.busy = lambda: _in_flight(worker)
        result = _run_with(scenario, worker)
    worker.close()
    with _Timer() as inside:
        inside_result = run_scenario(scenario, motion_planner=MotionPlanner(options, design=design))
    rows = [
        ("planner beside the update (worker), a plan in flight", _figures(beside.samples, True)),
        ("planner beside the update (worker), all updates", _figures(beside.samples, False)),
        ("planner inside the update (before), all updates", _figures(inside.samples, False)),
    ]
    _write(args, rows, result, inside_result)


def _run_with(scenario, worker: WorkerPlanService):
    from hrc_drake.cell.run import run as run_module

    original = run_module.shared_plan_service
    run_module.shared_plan_service = lambda options, design: worker
    try:
        return run_scenario(scenario)
    finally:
        run_module.shared_plan_service = original


def _write(args, rows, result, inside_result) -> None:
    lines = [
        "# The Supervisor's update while the planner works",
        "",
        f"`python benchmarks/bench_controller_update.py --scenario {args.scenario}"
        f"{' --lean' if args.lean else ''}` on {platform.machine()}, "
        f"{time.strftime('%Y-%m-%d')}: simulated time runs on while plans are computed "
        "(`run: {wait_for_planner: false}`); every Supervisor update timed (wall ms).",
        "",
        "| updates | n | median ms | p99 ms | max ms |",
        "|---|---|---|---|---|",
    ]
    for label, f in rows:
        lines.append(
            f"| {label} | {f['n']} | {f['median']:.3f} | {f['p99']:.3f} | {f['max']:.3f} |"
        )
    lines += [
        "",
        f"Both runs visit {' '.join(result.names)} (inside: {' '.join(inside_result.names)}), "
        f"terminal {result.done}/{inside_result.done}, collisions "
        f"{len(result.collisions)}/{len(inside_result.collisions)}.",
        "",
        "Target: the longest update while a plan is being computed is under 5 ms.",
    ]
    REPORT.parent.mkdir(parents=True, exist_ok=True)
    REPORT.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
