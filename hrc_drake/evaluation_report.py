"""The report of an evaluation's runs: the JSON summary (`summarise`: completion, times, idle
time, the interaction, and at cell level collisions, hand-overs and the failing runs with what
replays each alone), and the histogram of its times (`plot_times`).

Apart from the run loop (`hrc_drake.evaluate`), which calls `summarise` once the runs are
played: a report is read from the runs' results alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hrc_drake.evaluation_runs import RunResult, Setup, run_seed
from hrc_drake.tasks.interaction import Interaction


def summarise(
    setup: Setup, results: list[RunResult], runs: list[int] | None = None
) -> dict[str, Any]:
    """The JSON report of a list of runs; `runs` are their indices in the evaluation (default
    0, 1, ...: every run, in order), which name the failing ones at cell level."""
    runs = list(range(len(results))) if runs is None else runs
    report = {
        "decider": setup.decider,
        "operator_model": setup.operator_model,
        "params": dict(setup.params),
        "assembly": setup.space.spec.name,
        **_run_figures(results),
        **_idle_figures(results),
        **_interaction_figures(setup.interaction, results),
        "keep_model": setup.keep_model,
        "seed": setup.seed,
        "level": "task" if setup.cell is None else "cell",
        "times": [round(r.seconds, 3) for r in results if r.completed],
    }
    if setup.cell is not None:
        report.update(_cell_figures(setup, results, runs))
    return report


def _figure(x) -> float | None:
    """A report's figure: rounded to the millisecond (None stays None)."""
    return None if x is None else round(float(x), 3)


def _mean(values) -> float | None:
    """The mean as a figure; None, not NaN, when Ctrl-C came before any run finished."""
    return _figure(np.mean(values)) if values else None


def _run_figures(results: list[RunResult]) -> dict[str, Any]:
    """How many runs completed or were capped, their times (over the completed runs) and the
    mean tasks, undos and deviations per run."""
    done = [r for r in results if r.completed]
    times = np.array([r.seconds for r in done])
    return {
        "runs": len(results),
        "completed": len(done),
        "completion_rate": len(done) / len(results) if results else None,
        # Not terminal, ended by the run's own task cap with that reason (not a failure).
        "capped": sum(r.capped for r in results),
        "mean_time": _figure(times.mean() if len(done) else None),
        "p95_time": _figure(np.percentile(times, 95) if len(done) else None),
        "worst_time": _figure(times.max() if len(done) else None),
        "mean_tasks": _mean([r.tasks for r in results]),
        "mean_undos": _mean([r.undos for r in results]),
        "mean_deviations": _mean([r.deviations for r in results]),
    }


def _idle_figures(results: list[RunResult]) -> dict[str, Any]:
    """The robot's idle seconds at a boundary and the share of boundaries planned ahead."""
    idle = [x for r in results for x in r.idle]
    ready = [x for r in results for x in r.plan_ready]
    return {
        "mean_idle": round(float(np.mean(idle)), 4) if idle else 0.0,
        "p95_idle": round(float(np.percentile(idle, 95)), 4) if idle else 0.0,
        "plan_ready_rate": round(float(np.mean(ready)), 4) if ready else None,
    }


def _interaction_figures(interaction: Interaction, results: list[RunResult]) -> dict[str, Any]:
    """The interaction played and what it did: commits, re-targets, swaps, indication delays
    and the waits for them."""
    boundaries = sum(r.tasks for r in results)
    return {
        "interaction": interaction.mode,
        "interface": interaction.interface,
        "indication_delay": interaction.delay.to_json(),
        "commit_rate": round(sum(r.commits for r in results) / boundaries, 4)
        if boundaries
        else 0.0,
        "mean_retargets": _mean([r.retargets for r in results]),
        "mean_swaps": _mean([r.swaps for r in results]),
        "mean_indication_delay": _mean([r.indication_delay for r in results]),
        "mean_indication_wait": _mean([r.indication_wait for r in results]),
    }


def _cell_figures(setup: Setup, results: list[RunResult], runs: list[int]) -> dict[str, Any]:
    """What only cell runs report: collisions, hand-overs, the wall time the robot waited for
    the planner, the cell's description, the first errors and the failing runs."""
    errors = sorted({r.error for r in results if r.error and not (r.completed or r.capped)})
    wall_idle = [x for r in results for x in r.wall_idle]
    return {
        # How long the arm stood still for an indication the cell does not measure.
        "mean_indication_wait": None,
        "collisions": int(sum(r.collisions for r in results)),
        # Tasks the robot could not do and the operator did by hand (the runs went on).
        "handovers": int(sum(r.handovers for r in results)),
        "runs_with_handovers": int(sum(r.handovers > 0 for r in results)),
        "wall_mean_idle": round(float(np.mean(wall_idle)), 4) if wall_idle else 0.0,
        **setup.cell.describe(setup.space),
        "errors": errors[:5],
        "failures": failures(setup, results, runs),
    }


def stop_reason(result: RunResult) -> str:
    """Why a cell run failed, in one line: its error, else what kept it from passing."""
    if result.error:
        return result.error
    if not result.completed:
        last = result.states[-1] if result.states else "?"
        return f"ended in state {last}, not terminal"
    problems = []
    if result.collisions:
        problems.append(f"{result.collisions} robot collision(s)")
    if result.unsafe:
        problems.append(f"{result.unsafe} step(s) or contact(s) beyond ISO/TS 15066")
    return ", ".join(problems)


def failures(setup: Setup, results: list[RunResult], runs: list[int]) -> list[dict[str, Any]]:
    """The cell runs that did not complete, had robot collisions or broke the run's safety check
    (beyond ISO/TS 15066), each with what replays it alone (`CellRuns.replay`): its index, the
    operator's seed, model and parameters, the stop reason, the states it went through and the
    command."""
    out = []
    for run, r in zip(runs, results, strict=True):
        if (r.completed or r.capped) and not r.collisions and not r.unsafe:
            continue
        out.append(
            {
                "run": run,
                "seed": run_seed(setup.seed, run),
                "operator_model": setup.operator_model,
                "params": dict(setup.params),
                "completed": r.completed,
                "stop": stop_reason(r),
                "states": list(r.states),
                "collisions": r.collisions,
                "separation_violations": r.violations,
                "beyond_iso_15066": r.unsafe,
                "replay": setup.cell.replay(setup, run),
            }
        )
    return out


def plot_times(report: dict[str, Any], path: Path) -> None:
    """Histogram of the completed runs' assembly times (``report["times"]``)."""
    from hrc_drake.tasks.plots import plt, save_figure

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.hist(report["times"], bins=30, color="tab:blue")
    ax.set_xlabel("assembly time [s] (simulated)")
    ax.set_ylabel("runs")
    ax.set_title(
        f"{report['decider']} vs {report['operator_model']}: {report['completed']}/"
        f"{report['runs']} completed"
    )
    save_figure(fig, path)
