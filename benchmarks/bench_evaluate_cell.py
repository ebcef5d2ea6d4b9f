"""Deciders against operator populations through the physical cell -> benchmarks/reports/.

For each (decider, population) pair, `hrc_drake.evaluate` plays the same seeded runs twice: as
closed-loop simulations of the cell (`--cell`, full settings: 5 s bolting holds, the operator's
body and speed-and-separation monitoring on) and at task level with the cell's cost table. The
report compares the paper's Q-learning agent with ours in the cell, and how well the cost table
predicts the cell's times. Populations whose runs are all alike (`follows`, `habitual`) get two
runs, the random ones more. `slow` and `random` are left out here (`random`'s runs average 15
tasks, minutes of simulation each); `bench_population_sweep.py` runs every population in the
cell, lean.

Each pair is played in one interaction mode (``--interaction``, default `anticipate`: the decider
bets at each boundary, in the cell as at task level, and the simulated operator indicates after
the pointer's delay, the same draws at both levels; `wait`: the robot waits for it).

Results are kept per pair and mode in `benchmarks/reports/evaluate_cell.json`, so that
``--deciders mpc`` re-runs one decider and the report (a table per mode) and plot (anticipate)
are rebuilt from all pairs.

Usage: ``python benchmarks/bench_evaluate_cell.py [--runs 12] [--workers 2] [--deciders ...]
[--interaction anticipate|wait]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.run.costs import default_cost_table
from hrc_drake.cell.run.evaluate import CellOptions
from hrc_drake.evaluate import evaluate
from hrc_drake.evaluation_runs import Setup
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import ANTICIPATE, MODES, WAIT, make_interaction
from hrc_drake.tasks.spec import load_spec

DECIDERS = ["paper-q", "time", "mpc"]
POPULATIONS = ["follows", "habitual", "mistake-prone", "change-of-mind"]
DETERMINISTIC = {"follows", "habitual"}
HERE = Path(__file__).parent
RESULTS = HERE / "reports" / "evaluate_cell.json"
REPORT = HERE / "reports" / "evaluate_cell.md"
PLOT = HERE.parent / "docs" / "evaluation_cell.png"
KEEP = (
    "runs",
    "completed",
    "mean_time",
    "p95_time",
    "worst_time",
    "mean_tasks",
    "mean_undos",
    "mean_deviations",
    "mean_idle",
    "p95_idle",
    "wall_mean_idle",
    "plan_ready_rate",
    "commit_rate",
    "mean_retargets",
    "mean_swaps",
    "collisions",
    "errors",
    "wall_seconds",
)


# Pairs kept from before the interaction was built (no mode in their key): the robot waited for
# an answer that came at once.
AT_ONCE = "answered at once"


def key(decider: str, population: str, mode: str) -> str:
    """A pair's key in the results."""
    return f"{decider}|{population}" + ("" if mode == AT_ONCE else f"|{mode}")


def run_pair(
    space, costs, decider: str, population: str, runs: int, seed: int, workers: int, mode: str
):
    """The cell's and the task level's reports on the same seeded runs, in interaction `mode`
    at both levels."""
    interaction = make_interaction(mode)
    task = Setup(space, costs, decider, population, {}, seed, interaction)
    cell = Setup(space, costs, decider, population, {}, seed, interaction, cell=CellOptions())
    start = time.perf_counter()
    in_cell = evaluate(cell, runs, workers, progress=_progress(decider, population))
    print(f"  {time.perf_counter() - start:.0f} s", flush=True)
    at_task = evaluate(task, runs)
    return {
        "cell": {k: in_cell[k] for k in KEEP},
        "task": {k: at_task[k] for k in ("mean_time", "p95_time", "mean_tasks", "mean_undos")},
        "workers": workers,
    }


def _progress(decider, population):
    def show(done, total):
        print(f"\r{decider} vs {population}: run {done}/{total}", end="", flush=True)

    return show


def plot(results: dict, path: Path) -> None:
    """Mean cell time per decider and population (bars; ticks: the task level's prediction)."""
    from hrc_drake.tasks.plots import plt, save_figure

    mode = next((m for m in (ANTICIPATE, WAIT) if any(k.endswith(m) for k in results)), AT_ONCE)
    deciders = [d for d in DECIDERS if any(key(d, p, mode) in results for p in POPULATIONS)]
    fig, ax = plt.subplots(figsize=(8, 3.8))
    width = 0.8 / max(1, len(deciders))
    for k, d in enumerate(deciders):
        x = np.arange(len(POPULATIONS)) + (k - (len(deciders) - 1) / 2) * width
        pairs = [results.get(key(d, p, mode), {}) for p in POPULATIONS]
        cell = [r.get("cell", {}).get("mean_time") for r in pairs]
        task = [r.get("task", {}).get("mean_time") for r in pairs]
        ax.bar(x, [c or 0.0 for c in cell], width, label=d)
        ax.scatter(x, [t or np.nan for t in task], marker="_", color="black", s=80, zorder=3)
    ax.set_xticks(np.arange(len(POPULATIONS)), POPULATIONS)
    ax.set_ylim(bottom=30.0)  # the differences are a few seconds of ~35-45 s
    ax.set_ylabel("assembly time [s], from 30 s\n(bar: cell, tick: task level)")
    ax.set_title(f"flange case in the cell ({mode}): the paper's Q-learning agent against ours")
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=110)


def report(results: dict, seed: int) -> str:
    """The markdown report of all pairs."""
    lines = [
        "# Deciders against operator populations, through the physical cell",
        "",
        "`python benchmarks/bench_evaluate_cell.py` (seed "
        f"{seed}): the flange case in the cell at full settings (5 s bolting holds, the "
        "operator's body and speed and separation monitoring on); each run is a closed-loop "
        "simulation in which the decider proposes, the population's model answers and the "
        "decider learns from what the cell observed; a fresh motion planner per run. The same "
        "seeded runs are also played at task level with the cell's cost table ('task' "
        "columns). Times are simulated seconds over the completed runs; idle is the wall time "
        "the robot waited for the planner after the operator's answer, per boundary "
        "(simulated time stands still meanwhile); commits, "
        "re-targets and swaps as the cell's Supervisor recorded them (per boundary, per run).",
        "",
    ]
    for mode in (ANTICIPATE, WAIT, AT_ONCE):
        if any(key(d, p, mode) in results for d in DECIDERS for p in POPULATIONS):
            lines += _mode_table(results, mode)
    lines += [
        f"Plot: `docs/{PLOT.name}` (bars: cell mean; ticks: task-level mean on the same seeds).",
        "'wall per run' is the wall time of a pair times its workers over its runs.",
        "",
    ]
    return "\n".join(lines)


def _wall_idle(cell: dict) -> float:
    """The mean wall-clock idle per boundary of a pair's cell runs. Results kept from before
    `mean_idle` became simulated seconds hold the wall time under that key."""
    return cell.get("wall_mean_idle", cell["mean_idle"])


def _mode_table(results: dict, mode: str) -> list[str]:
    title = {
        ANTICIPATE: "anticipate (pointer)",
        WAIT: "wait (pointer)",
        AT_ONCE: "answered at once (kept from a run before the indication delay was built)",
    }[mode]
    lines = [
        f"## {title}",
        "",
        "| decider | operator | runs | completed | cell mean [s] | cell p95 [s] | task mean [s] |"
        " cell / task | tasks | undos | deviations | commits | re-targets | swaps | plan ready |"
        " idle mean [s] | collisions | wall per run [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for d in DECIDERS:
        for p in POPULATIONS:
            r = results.get(key(d, p, mode))
            if r is None:
                continue
            c, t = r["cell"], r["task"]
            ratio = c["mean_time"] / t["mean_time"] if c["mean_time"] and t["mean_time"] else None
            lines.append(
                f"| {d} | {p} | {c['runs']} | {c['completed']} | {c['mean_time']} | "
                f"{c['p95_time']} | {t['mean_time']} | "
                f"{'' if ratio is None else f'{ratio:.3f}'} | {c['mean_tasks']} | "
                f"{c['mean_undos']} | {c['mean_deviations']} | {c.get('commit_rate', 0.0)} | "
                f"{c.get('mean_retargets', 0.0)} | {c.get('mean_swaps', 0.0)} | "
                f"{c['plan_ready_rate']} | "
                f"{_wall_idle(c)} | {c['collisions']} | "
                f"{c['wall_seconds'] * r['workers'] / c['runs']:.1f} |"
            )
            if c["errors"]:
                lines.append(f"|  | errors: {'; '.join(c['errors'])} |")
    return [*lines, ""]


def main() -> None:
    """Run the pairs asked for, then rebuild the report and plot from every pair kept."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=12, help="runs of the random populations")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--deciders", nargs="*", default=DECIDERS, choices=DECIDERS)
    parser.add_argument("--populations", nargs="*", default=POPULATIONS, choices=POPULATIONS)
    parser.add_argument("--interaction", default=ANTICIPATE, choices=MODES)
    parser.add_argument("--report-only", action="store_true", help="rebuild report and plot")
    args = parser.parse_args()
    if args.report_only:
        args.deciders = []
    space = generate_states(load_spec())
    costs = default_cost_table(space)
    results = json.loads(RESULTS.read_text()) if RESULTS.is_file() else {}
    for d in args.deciders:
        for p in args.populations:
            runs = 2 if p in DETERMINISTIC else args.runs
            results[key(d, p, args.interaction)] = run_pair(
                space, costs, d, p, runs, args.seed, args.workers, args.interaction
            )
            atomic_write_text(RESULTS, json.dumps(results, indent=1, sort_keys=True) + "\n")
    atomic_write_text(REPORT, report(results, args.seed))
    plot(results, PLOT)
    print(f"wrote {REPORT}, {RESULTS} and {PLOT}")


if __name__ == "__main__":
    main()
