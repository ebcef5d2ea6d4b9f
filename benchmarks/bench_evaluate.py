"""Monte Carlo evaluation of the deciders on operator populations -> benchmarks/reports/evaluate.md.

Side by side in one run, on the flange case with the cell's cost table (computed once and
cached, `hrc_drake.cell.costs.default_cost_table`):

1. every (decider, operator model) pair: completion, mean / p95 / worst simulated seconds;
2. mpc against exact on the habitual and mistake-prone populations, and mpc when its operator
   model is kept across runs (one operator, many assemblies) instead of reset per run;
3. evaluation throughput, serial against ``--workers 2``;
4. the mpc re-solve time per task boundary: flange, and a generated assembly of ~10^5 states
   (`generated_spec(9, 5, 1)`: 95,306 states) with a synthetic cost table.

Usage: ``python benchmarks/bench_evaluate.py [--runs 10000]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from generated import generated_spec

from hrc_drake.atomic import atomic_write_text
from hrc_drake.evaluate import Setup, evaluate, simulate_run
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import operator_seconds, table_from_seconds, task_edges
from hrc_drake.tasks.deciders import DECIDERS, MpcDecider
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

MODELS = ["follows", "random", "habitual", "mistake-prone", "change-of-mind", "slow"]
REPORT = Path(__file__).parent / "reports" / "evaluate.md"
PLOT = Path(__file__).parent.parent / "docs" / "evaluation.png"


def plot_means(table: dict, path: Path) -> None:
    """Mean and p95 simulated seconds per population: the paper's agent against ours."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hrc_drake.atomic import atomic_write_bytes

    deciders = ["paper-q", "time", "mpc", "worst-case"]
    fig, ax = plt.subplots(figsize=(8, 3.8))
    width = 0.8 / len(deciders)
    for k, d in enumerate(deciders):
        x = np.arange(len(MODELS)) + (k - (len(deciders) - 1) / 2) * width
        mean = [table[d, m]["mean_time"] for m in MODELS]
        p95 = [table[d, m]["p95_time"] for m in MODELS]
        ax.bar(x, mean, width, label=d)
        ax.scatter(x, p95, marker="_", color="black", s=60, zorder=3)
    ax.set_xticks(np.arange(len(MODELS)), MODELS)
    ax.set_yscale("log")
    ax.set_ylabel("assembly time [s] (bar: mean, tick: p95)")
    ax.set_title("flange case, task level: the paper's Q-learning agent against ours")
    ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def synthetic_costs(space):
    """Seconds per edge: 5 s of robot motion + 0.1 s per token index, plus the bolting time."""
    seconds = {}
    for state, task in task_edges(space):
        robot = 5.0 if task == UNDO else 5.0 + 0.1 * space.tokens.index(task)
        seconds[state, task] = robot + operator_seconds(space.spec, state, task)
    return table_from_seconds(space, seconds, cell_hash="synthetic")


def ms(values) -> str:
    v = np.array(values) * 1e3
    return f"median {np.median(v):.2f} ms, p95 {np.percentile(v, 95):.2f} ms, max {v.max():.2f} ms"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    from hrc_drake.cell.costs import default_cost_table

    space = generate_states(load_spec(models_dir() / "assemblies" / "flange.yaml"))
    costs = default_cost_table(space)
    lines = [
        "# Monte Carlo evaluation of the deciders (task level)",
        "",
        f"`python benchmarks/bench_evaluate.py --runs {args.runs}` (seed {args.seed}): the",
        "flange case, the cell's cost table (cached), `hrc_drake.evaluate` defaults: a run",
        "ends in a terminal",
        "state or after 100 tasks; a deviation from the proposal costs 1 s more; idle time at",
        "boundaries is 0 at task level (the cell plans the predicted tasks ahead). Times are",
        "simulated seconds over the completed runs. Operator models at their default parameters",
        "(habitual: S23 first; mistake-prone p = 0.2; change-of-mind p = 0.2; slow growth 0.1).",
        "Each run resets the decider: `mpc` learns within a run only (see section 2).",
        "",
        "## 1. Every decider against every population",
        "",
        f"{args.runs} runs per pair.",
        "",
        "| decider | operator | completed | mean [s] | p95 [s] | worst [s] | tasks | undos |"
        " deviations |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    table = {}
    for decider in DECIDERS:
        for model in MODELS:
            start = time.perf_counter()
            r = evaluate(Setup(space, costs, decider, model, {}, args.seed), args.runs)
            table[decider, model] = r
            lines.append(
                f"| {decider} | {model} | {100 * r['completion_rate']:.1f} % | {r['mean_time']} | "
                f"{r['p95_time']} | {r['worst_time']} | {r['mean_tasks']} | {r['mean_undos']} | "
                f"{r['mean_deviations']} |"
            )
            print(f"{decider:10} {model:15} {time.perf_counter() - start:6.1f} s", file=sys.stderr)

    plot_means(table, PLOT)
    lines += ["", f"Plot: `docs/{PLOT.name}`.", "", "## 2. mpc against exact", ""]
    lines += ["| population | exact mean [s] | mpc mean [s] | mpc faster by |", "|---|---|---|---|"]
    for model in ("habitual", "mistake-prone"):
        e, m = table["exact", model]["mean_time"], table["mpc", model]["mean_time"]
        lines.append(f"| {model} | {e} | {m} | {100 * (e - m) / e:.1f} % |")
    # One operator, many assemblies: the model is kept across runs.
    runs_kept = min(args.runs, 1000)
    lines += [
        "",
        f"mpc with its operator model kept across {runs_kept} successive runs of one operator",
        "(not reset; serial only), against exact on the same operators:",
        "",
        "| population | exact mean [s] | mpc kept mean [s] | faster by |",
        "|---|---|---|---|",
    ]
    for model in ("habitual", "mistake-prone"):
        mpc = MpcDecider(space, costs)
        times = []
        for i in range(runs_kept):
            op = make_operator_model(model, space, seed=i)
            times.append(simulate_run(space, costs, mpc, op).seconds)
        e, m = table["exact", model]["mean_time"], float(np.mean(times))
        lines.append(f"| {model} | {e} | {m:.3f} | {100 * (e - m) / e:.1f} % |")

    lines += ["", "## 3. Throughput, serial against --workers 2", ""]
    lines += ["| decider, operator | runs | workers | wall [s] | runs/s |", "|---|---|---|---|---|"]
    same = []
    for workers in (1, 2):
        s = Setup(space, costs, "mpc", "mistake-prone", {}, args.seed)
        r = evaluate(s, args.runs, workers=workers)
        same.append({k: v for k, v in r.items() if not k.startswith("wall_") and k != "workers"})
        lines.append(
            f"| mpc, mistake-prone | {args.runs} | {workers} | {r['wall_seconds']} | "
            f"{r['wall_runs_per_second']} |"
        )
    lines += [
        "",
        f"Same report serial and parallel: {same[0] == same[1]}. The machine has 2 cores shared "
        "with other jobs; the parallel figure includes starting the spawned processes.",
    ]

    lines += ["", "## 4. mpc re-solve time per task boundary", ""]
    mpc = MpcDecider(space, costs)
    for i in range(200):
        mpc.reset()
        simulate_run(space, costs, mpc, make_operator_model("mistake-prone", space, seed=i))
    lines.append(f"- flange (20 states), 200 mistake-prone runs: {ms(mpc.solve_seconds)}.")
    big = generate_states(generated_spec(9, 5, 1))
    start = time.perf_counter()
    big_costs = synthetic_costs(big)
    mid = time.perf_counter()
    mpc_big = MpcDecider(big, big_costs)
    built = time.perf_counter() - mid
    for i in range(10):
        mpc_big.reset()
        op = make_operator_model("mistake-prone", big, seed=i, p=0.3)
        simulate_run(big, big_costs, mpc_big, op)
    first = mpc_big.solve_seconds[0]
    lines.append(
        f"- generated (9 slots, 5 F, 1 S: {big.n_states} states), 10 mistake-prone runs "
        f"(p = 0.3): {ms(mpc_big.solve_seconds)}; the first boundary (from the empty base, the "
        f"whole graph) {1e3 * first:.1f} ms. Setup once: synthetic cost table "
        f"{mid - start:.1f} s, MDP and initial values {built:.1f} s."
    )
    lines.append("")
    REPORT.parent.mkdir(exist_ok=True)
    atomic_write_text(REPORT, "\n".join(lines))
    print(f"wrote {REPORT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
