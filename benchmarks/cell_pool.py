"""Closed-loop cell runs spread over a process pool, shared by the cell benchmarks."""

from __future__ import annotations

import multiprocessing
import sys
import time
from collections.abc import Callable, Sequence

_PLANNERS: dict = {}
# The scenario text of a cell with late, noisy readings on every measured port and the camera's
# verdicts in place of contact's (`bench_camera.py`, `bench_faults.py --camera`).
CAMERA_TEXT = "{sensors: {preset: realistic, configuration: camera}}"


def pooled_loop(scenario, key: str):
    """The closed loop of `scenario` in a pool's worker. A pool's worker cannot start a
    planning worker of its own: it plans in-process, one planner per `key` (a cell), its plans
    cached across the worker's runs."""
    from hrc_drake.cell.run.run import build_closed_loop, shared_planner
    from hrc_drake.cell.scenario import cell_design, motion_options
    from hrc_drake.tasks.spec import load_spec

    if key not in _PLANNERS:
        design = cell_design(scenario, load_spec(scenario.assembly_path))
        _PLANNERS[key] = shared_planner(motion_options(scenario), design)
    return build_closed_loop(scenario, motion_planner=_PLANNERS[key])


def desk_run(population: str, interaction: str, seed: int, setting: str, lean: bool):
    """The closed-loop run (`RunResult`) of `shared-desk` with an operator of `population`
    (its `seed`) in `interaction` mode, under the scenario text `setting`, lean or not."""
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    operator = (
        f"{{operator: {{model: {population}, seed: {seed}}}, interaction: {{mode: {interaction}}}}}"
    )
    texts = [operator, setting, *([LEAN] if lean else [])]
    scenario = load_cell_scenario("shared-desk", texts)
    return pooled_loop(scenario, scenario.assembly).run()


def error_lines(runs: list[dict]) -> list[str]:
    """A report's "Errors" section: each run (a dict with its `job` and `error`) that ended in
    an error, none if none did."""
    errors = [r for r in runs if r.get("error")]
    if not errors:
        return []
    return ["## Errors", "", *(f"- {r['job']}: {r['error']}" for r in errors), ""]


def publish(text: str, report, lean: bool) -> None:
    """Print a benchmark's report; unless it ran `lean` (a quick look), also write it to the
    `report` path (atomically)."""
    from hrc_drake.atomic import atomic_write_text

    if lean:
        print(text)
        return
    atomic_write_text(report, text)
    print(f"{text}\nwritten to {report}")


def write_report(text: str, report) -> None:
    """Write a benchmark's report to the `report` path (atomically), lean or not, and say
    where (`bench_separation.py`: its `--out` chooses the path)."""
    from hrc_drake.atomic import atomic_write_text

    atomic_write_text(report, text)
    print(f"wrote {report}")


# Runs a worker process makes before a fresh one takes over. A finished run's diagram is never
# freed (pydrake keeps the cycles between a diagram and its Python systems alive: measured, 46 MB
# a lean `shared-desk` run, 350 MB with the safety sensor's three robot models), so a worker
# that ran 40 sensor runs held 12 GB.
RUNS_PER_WORKER = 4


def run_pool(one_run: Callable, jobs: Sequence, workers: int) -> tuple[list, float]:
    """(`one_run` of every job in order, wall seconds), over `workers` spawned processes (each
    replaced after `RUNS_PER_WORKER` runs), with a progress line on stderr."""
    start = time.perf_counter()
    runs = []
    context = multiprocessing.get_context("spawn")
    with context.Pool(min(workers, len(jobs)), maxtasksperchild=RUNS_PER_WORKER) as pool:
        for k, run in enumerate(pool.imap(one_run, jobs), 1):
            runs.append(run)
            elapsed = time.perf_counter() - start
            print(f"\r{k}/{len(jobs)} runs ({elapsed:.0f} s)", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return runs, time.perf_counter() - start
