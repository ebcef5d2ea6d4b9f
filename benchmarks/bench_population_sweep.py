"""The cell against every operator population -> benchmarks/reports/population_sweep.md.

Every built-in population (`hrc_drake.hri.populations`) against three deciders (the paper's
Q-learning agent, the exact minimum-effort policy and the model-predictive one), 20 runs a pair,
through the physical cell with lean settings (0.5 s bolting holds), anticipating. Each run is an
`evaluate --cell` run: the decider proposes, the population's model answers, the cell plays it.
A run passes when it ends terminal, or by its own task cap (`run.max_steps`, with the reason: an
operator who keeps undoing can outlast any cap), with no robot collision and no separation
violation; the report lists every run that did not, with the command that replays it alone.

Results are kept per pair in `benchmarks/reports/population_sweep.json`, so that an interrupted
sweep goes on where it stopped (``--fresh`` starts over) and the report is rebuilt from all pairs.

Usage: ``python benchmarks/bench_population_sweep.py [--runs 20] [--workers 2] [--deciders ...]
[--populations ...] [--fresh]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.run.costs import default_cost_table
from hrc_drake.cell.run.evaluate import CellOptions
from hrc_drake.cell.scenario import LEAN
from hrc_drake.evaluate import evaluate
from hrc_drake.evaluation_runs import Setup
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import make_interaction
from hrc_drake.tasks.spec import load_spec

DECIDERS = ["paper-q", "exact", "mpc"]
# Random last: its runs average 15-17 tasks, several times the others' wall time.
POPULATIONS = ["follows", "habitual", "mistake-prone", "change-of-mind", "slow", "random"]
HERE = Path(__file__).parent
RESULTS = HERE / "reports" / "population_sweep.json"
REPORT = HERE / "reports" / "population_sweep.md"
KEEP = (
    "runs",
    "completed",
    "capped",
    "collisions",
    "handovers",
    "mean_time",
    "worst_time",
    "mean_tasks",
    "mean_undos",
    "failures",
    "errors",
    "wall_seconds",
)


def key(decider: str, population: str) -> str:
    """A pair's key in the results."""
    return f"{decider}|{population}"


def run_pair(space, costs, decider: str, population: str, runs: int, seed: int, workers: int):
    """The cell's report on `runs` seeded runs of one pair, lean and anticipating."""
    cell = CellOptions(overrides=(LEAN,))
    setup = Setup(
        space, costs, decider, population, {}, seed, make_interaction("anticipate"), cell=cell
    )

    def show(done, total):
        print(f"\r{decider} vs {population}: run {done}/{total}", end="", flush=True)

    start = time.perf_counter()
    report = evaluate(setup, runs, workers, progress=show)
    print(f"  {time.perf_counter() - start:.0f} s", flush=True)
    kept = {k: report.get(k) for k in KEEP}
    kept["violations"] = sum(f["separation_violations"] for f in report["failures"])
    kept["workers"] = workers
    return kept


def passed(r: dict) -> int:
    """Runs that ended terminal or by their cap with no collision or violation."""
    return r["runs"] - len(r["failures"])


def report(results: dict, seed: int, runs: int) -> str:
    """The markdown report: a table per population, then every failing run."""
    lines = [
        "# The cell against every operator population",
        "",
        f"`python benchmarks/bench_population_sweep.py --runs {runs}` (seed {seed}): the "
        "flange case through the physical cell, lean (0.5 s bolting holds), anticipating, "
        "predictive separation; each run a closed-loop simulation in which the decider "
        "proposes and the population's model answers. *passed*: terminal, or ended by the "
        "run's own task cap (`run.max_steps`, 30; *capped*), with no robot collision and no "
        "separation violation. Times are simulated seconds over the terminal runs.",
        "",
        "| population | decider | runs | passed | terminal | capped | collisions | violations |"
        " handovers | mean time [s] | worst [s] | tasks | undos | wall per run [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    failing = []
    for p in POPULATIONS:
        for d in DECIDERS:
            r = results.get(key(d, p))
            if r is None:
                continue
            wall = r["wall_seconds"] * r["workers"] / r["runs"] if r["runs"] else 0.0
            lines.append(
                f"| {p} | {d} | {r['runs']} | {passed(r)} | {r['completed']} | {r['capped']} | "
                f"{r['collisions']} | {r['violations']} | {r['handovers']} | {r['mean_time']} | "
                f"{r['worst_time']} | {r['mean_tasks']} | {r['mean_undos']} | {wall:.1f} |"
            )
            failing += [(d, p, f) for f in r["failures"]]
    total = sum(r["runs"] for r in results.values())
    ok = sum(passed(r) for r in results.values())
    lines += ["", f"**{ok} of {total} runs passed.**", ""]
    if failing:
        lines += ["## Failing runs", ""]
        for d, p, f in failing:
            lines += [
                f"- {d} vs {p}, run {f['run']} (seed {f['seed']}): {f['stop']}; states "
                f"{' '.join(f['states'])}",
                f"  `{f['replay']}`",
            ]
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    """Run the pairs not yet kept (or all with --fresh), then rebuild the report."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per pair")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--deciders", nargs="*", default=DECIDERS, choices=DECIDERS)
    parser.add_argument("--populations", nargs="*", default=POPULATIONS, choices=POPULATIONS)
    parser.add_argument("--fresh", action="store_true", help="forget the pairs kept before")
    args = parser.parse_args()
    space = generate_states(load_spec())
    costs = default_cost_table(space)
    results = {} if args.fresh or not RESULTS.is_file() else json.loads(RESULTS.read_text())
    for p in args.populations:
        for d in args.deciders:
            if key(d, p) in results and results[key(d, p)]["runs"] == args.runs:
                continue
            results[key(d, p)] = run_pair(space, costs, d, p, args.runs, args.seed, args.workers)
            atomic_write_text(RESULTS, json.dumps(results, indent=1, sort_keys=True) + "\n")
    atomic_write_text(REPORT, report(results, args.seed, args.runs))
    print(f"wrote {REPORT} and {RESULTS}")


if __name__ == "__main__":
    main()
