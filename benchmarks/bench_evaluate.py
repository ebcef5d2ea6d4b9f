"""Monte Carlo evaluation of the deciders on operator populations -> benchmarks/reports/evaluate.md.

Side by side in one run, on the flange case with the cell's cost table (computed once and
cached, `hrc_drake.cell.run.costs.default_cost_table`):

1. every (decider, operator model) pair: completion, mean / p95 / worst simulated seconds;
2. mpc against exact on the habitual and mistake-prone populations, mpc when its operator model
   is kept across runs (one operator, many assemblies) instead of reset per run, and an oracle:
   the exact policy in seconds under the population's true model (`oracle_decider`), on the
   same seeds. The oracle's gain over exact is the most any decider can gain there;
3. evaluation throughput, serial against ``--workers 2``;
4. the mpc re-solve time per task boundary: flange, and a generated assembly of ~10^5 states
   (`generated_spec(9, 5, 1)`: 95,306 states) with a synthetic cost table.

Usage: ``python benchmarks/bench_evaluate.py [--runs 10000] [--section N]``; with ``--section``
only that section is run and printed (the report is written by a full run only).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from bench_interaction import MISTAKE_P, expected_seconds, oracle_decider, play
from generated import generated_spec

from hrc_drake.atomic import atomic_write_text
from hrc_drake.evaluate import evaluate, simulate_run
from hrc_drake.evaluation_runs import Setup
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import (
    operator_seconds,
    table_from_seconds,
    task_edges,
    uniform_bets,
)
from hrc_drake.tasks.deciders import DECIDERS, make_decider
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import make_interaction
from hrc_drake.tasks.mpc import MpcDecider
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

MODELS = ["follows", "random", "habitual", "mistake-prone", "change-of-mind", "slow"]
REPORT = Path(__file__).parent / "reports" / "evaluate.md"
PLOT = Path(__file__).parent.parent / "docs" / "evaluation.png"


def plot_means(table: dict, path: Path) -> None:
    """Mean and p95 simulated seconds per population, every decider (the paper's agent, the
    exact unit-cost policy and ours), one panel per operator model (columns) and figure (rows:
    mean, p95), on linear axes fitted to each panel: the deciders differ by fractions of a
    second within a population and by tens of seconds across populations, so a shared axis (or
    a log one) would hide the differences that matter. Every value is printed beside its dot.
    `table[decider, model]` is a `summarise` report."""
    from matplotlib.ticker import MaxNLocator

    from hrc_drake.tasks.plots import plt, save_figure

    deciders, models = list(DECIDERS), MODELS
    rows = (("mean_time", "mean [s]"), ("p95_time", "p95 [s]"))
    fig, axes = plt.subplots(
        len(rows), len(models), figsize=(2.3 * len(models), 1.2 + 0.5 * len(deciders) * 2)
    )
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    y = np.arange(len(deciders))[::-1]
    for r, (key, label) in enumerate(rows):
        for c, model in enumerate(models):
            ax = axes[r][c]
            values = [table[d, model][key] for d in deciders]
            ax.scatter(values, y, c=[colours[k % len(colours)] for k in range(len(deciders))])
            low, high = min(values), max(values)
            pad = max(0.15 * (high - low), 0.02 * high, 0.05)
            ax.set_xlim(low - pad, high + 3 * pad)
            for value, yy in zip(values, y, strict=True):
                ax.annotate(
                    f"{value:.2f}",
                    (value, yy),
                    xytext=(4, 0),
                    textcoords="offset points",
                    va="center",
                    fontsize=7,
                )
            ax.set_ylim(-0.6, len(deciders) - 0.4)
            ax.set_yticks(y, deciders if c == 0 else [""] * len(deciders))
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.tick_params(axis="x", labelsize=7)
            ax.grid(axis="x", alpha=0.3)
            if r == 0:
                ax.set_title(model, fontsize=9)
            if c == 0:
                ax.set_ylabel(label)
    fig.suptitle(
        "flange case, task level, 10,000 runs per pair: the paper's Q-learning agent against ours",
        fontsize=10,
    )
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def synthetic_costs(space):
    """Seconds per edge: 5 s of robot motion + 0.1 s per token index, plus the bolting time;
    every carry from 2.5 s to 4 s, every re-target 0.8 s and swap 4 s (about the flange's)."""
    seconds = {}
    for state, task in task_edges(space):
        robot = 5.0 if task == UNDO else 5.0 + 0.1 * space.tokens.index(task)
        seconds[state, task] = robot + operator_seconds(space.spec, state, task)
    bets = uniform_bets(space, retarget=0.8, swap=4.0)
    return table_from_seconds(space, seconds, "synthetic", carry=(2.5, 4.0), bets=bets)


def ms(values) -> str:
    v = np.array(values) * 1e3
    return f"median {np.median(v):.2f} ms, p95 {np.percentile(v, 95):.2f} ms, max {v.max():.2f} ms"


def section_all(space, costs, args, table: dict) -> list[str]:
    """1. every (decider, operator model) pair; fills `table`."""
    lines = [
        "## 1. Every decider against every population",
        "",
        f"{args.runs} runs per pair.",
        "",
        "| decider | operator | completed | mean [s] | p95 [s] | worst [s] | tasks | undos |"
        " deviations | planned ahead | idle [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for decider in DECIDERS:
        for model in MODELS:
            start = time.perf_counter()
            r = evaluate(Setup(space, costs, decider, model, {}, args.seed), args.runs)
            table[decider, model] = r
            lines.append(
                f"| {decider} | {model} | {100 * r['completion_rate']:.1f} % | {r['mean_time']} | "
                f"{r['p95_time']} | {r['worst_time']} | {r['mean_tasks']} | {r['mean_undos']} | "
                f"{r['mean_deviations']} | {100 * r['plan_ready_rate']:.1f} % | {r['mean_idle']} |"
            )
            print(f"{decider:10} {model:15} {time.perf_counter() - start:6.1f} s", file=sys.stderr)
    plot_means(table, PLOT)
    return [
        *lines,
        "",
        "*planned ahead*: boundaries whose task the decider predicted (its proposal; for mpc "
        "also the answers its model expects with probability >= 0.1), planned while the operator "
        "bolted; *idle*: mean robot idle per boundary, 0.21 s (the median planning time) at the "
        "others.",
        "",
        f"Plot: `docs/{PLOT.name}`.",
    ]


def section_oracle(space, costs, args, table: dict) -> list[str]:
    """2. exact, time, mpc, mpc kept across runs and the oracle on habitual and mistake-prone."""
    interaction = make_interaction()
    populations = ("habitual", "mistake-prone")
    for decider in ("exact", "time", "mpc"):
        for model in populations:
            if (decider, model) not in table:
                setup = Setup(space, costs, decider, model, {}, args.seed)
                table[decider, model] = evaluate(setup, args.runs)
    lines = [
        "## 2. mpc against exact, and the most any decider can gain",
        "",
        f"{args.runs} runs per column, on the same operators (the seeds of `evaluate`). *mpc "
        "kept*: one",
        "operator, many assemblies: the operator model is kept across the runs instead of",
        "reset (serial; `evaluate --keep-model`). *oracle*: the exact policy in seconds under the",
        "population's true model, the interaction priced in (habitual: propose and commit to the",
        "habit `S23` first, the operator performs it anyway, then the fastest route of an",
        f"operator who follows; mistake-prone: the MDP with mistake probability {MISTAKE_P}). No",
        "decider can beat it on average, so *oracle gain* is the most any decider can be faster",
        "than exact on that population (`benchmarks/bench_interaction.py` has the same with",
        "the commit rates, re-targets and swaps).",
        "",
        "| population | exact [s] | time [s] | mpc [s] | mpc kept [s] | oracle [s] | "
        "mpc faster | mpc kept faster | oracle gain |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    noise, learned = {}, {}
    for model in populations:
        mpc = MpcDecider(space, costs, interaction)
        kept = play(space, costs, mpc, model, args.runs, args.seed, interaction, True)
        learned[model] = mpc
        oracle = oracle_decider(space, costs, interaction, model)
        best = play(space, costs, oracle, model, args.runs, args.seed, interaction)
        noise[model] = np.std(best["times"]) / np.sqrt(len(best["times"]))
        e, t, m = (table[d, model]["mean_time"] for d in ("exact", "time", "mpc"))
        k, o = kept["mean_time"], best["mean_time"]
        lines.append(
            f"| {model} | {e} | {t} | {m} | {k} | {o} | {100 * (e - m) / e:.1f} % | "
            f"{100 * (e - k) / e:.1f} % | {100 * (e - o) / e:.1f} % |"
        )
    # Mistake-prone is random: expected seconds by policy evaluation, without sampling noise.
    deciders = {
        "exact": make_decider("exact", space, costs),
        "time": make_decider("time", space, costs),
        "mpc kept (its policy after the runs)": learned["mistake-prone"],
        "oracle": oracle_decider(space, costs, interaction, "mistake-prone"),
    }
    expected = {
        k: expected_seconds(space, costs, interaction, d, MISTAKE_P) for k, d in deciders.items()
    }
    e = expected["exact"]
    lines += [
        "",
        "Habitual is deterministic but for the indication delays. Mistake-prone is not: the",
        f"standard error of a mean of {args.runs} runs is about "
        f"{noise['mistake-prone']:.2f} s, and deciders that take different routes draw",
        "different mistakes from the same seeds, so differences below ~0.3 s there are noise.",
        f"Expected seconds on mistake-prone (p = {MISTAKE_P}) of the deciders' policies and",
        "bets, by policy evaluation (no sampling):",
        "",
        "| policy | expected [s] | faster than exact |",
        "|---|---|---|",
    ]
    for name, value in expected.items():
        lines.append(f"| {name} | {value:.3f} | {100 * (e - value) / e:.2f} % |")
    return lines


def section_throughput(space, costs, args) -> list[str]:
    """3. evaluation throughput, serial against --workers 2 and --ray (when installed)."""
    lines = ["## 3. Throughput, serial against --workers 2 and --ray", ""]
    lines += ["| decider, operator | runs | workers | wall [s] | runs/s |", "|---|---|---|---|---|"]
    same = []
    skip = ("workers", "backend")
    modes = [(1, False), (2, False)]
    if importlib.util.find_spec("ray") is not None:
        modes.append((2, True))
    for workers, on_ray in modes:
        s = Setup(space, costs, "mpc", "mistake-prone", {}, args.seed)
        r = evaluate(s, args.runs, workers=workers, ray=on_ray)
        same.append({k: v for k, v in r.items() if not k.startswith("wall_") and k not in skip})
        lines.append(
            f"| mpc, mistake-prone | {args.runs} | {workers} ({r['backend']}) | "
            f"{r['wall_seconds']} | {r['wall_runs_per_second']} |"
        )
    return [
        *lines,
        "",
        f"Same report serial, in processes and on Ray: {all(x == same[0] for x in same)}. The "
        "machine has 2 cores shared with other jobs; the parallel figures include starting the "
        "spawned processes (and the local Ray instance, about 3 s).",
    ]


def section_resolve(space, costs, args) -> list[str]:
    """4. the mpc re-solve time per task boundary, flange and ~10^5 states."""
    lines = ["## 4. mpc re-solve time per task boundary", ""]
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
    firsts = []
    for i in range(10):
        mpc_big.reset()
        op = make_operator_model("mistake-prone", big, seed=i, p=0.3)
        firsts.append(len(mpc_big.solve_seconds))
        simulate_run(big, big_costs, mpc_big, op)
    first = [mpc_big.solve_seconds[j] for j in firsts]
    lines.append(
        f"- generated (9 slots, 5 F, 1 S: {big.n_states} states), 10 mistake-prone runs "
        f"(p = 0.3): {ms(mpc_big.solve_seconds)}; the first boundary of each run (from the empty "
        f"base, the whole graph): {ms(first)}, of which the very first (cold: it also lays out "
        f"the subtree, kept for later runs) {1e3 * first[0]:.1f} ms. Setup once: synthetic cost "
        f"table {mid - start:.1f} s, MDP and initial values {built:.1f} s."
    )
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--section", type=int, choices=(1, 2, 3, 4), help="run and print this section only"
    )
    args = parser.parse_args()
    from hrc_drake.cell.run.costs import default_cost_table

    space = generate_states(load_spec(models_dir() / "assemblies" / "flange.yaml"))
    costs = default_cost_table(space)
    sections = {
        1: lambda table: section_all(space, costs, args, table),
        2: lambda table: section_oracle(space, costs, args, table),
        3: lambda table: section_throughput(space, costs, args),
        4: lambda table: section_resolve(space, costs, args),
    }
    if args.section is not None:
        print("\n".join(sections[args.section]({})))
        return 0
    lines = [
        "# Monte Carlo evaluation of the deciders (task level)",
        "",
        f"`python benchmarks/bench_evaluate.py --runs {args.runs}` (seed {args.seed}): the",
        "flange case, the cell's cost table (cached), `hrc_drake.evaluate` defaults: a run",
        "ends in a terminal state or after 100 tasks; the robot anticipates (pointer delay,",
        "lognormal, median 2 s: it starts on its proposal or waits for the indication, and a",
        "wrong bet costs its re-target or swap; see `benchmarks/reports/interaction.md`); it",
        "idles 0.21 s at a boundary whose task was not planned ahead (see section 1). Times are",
        "simulated seconds over the completed runs. Operator models at their default parameters",
        "(habitual: S23 first; mistake-prone p = 0.2; change-of-mind p = 0.2; slow growth 0.1).",
        "Each run resets the decider: `mpc` learns within a run only (see section 2).",
        "",
    ]
    table: dict = {}
    for number in sorted(sections):
        lines += [*sections[number](table), ""]
    REPORT.parent.mkdir(exist_ok=True)
    atomic_write_text(REPORT, "\n".join(lines))
    print(f"wrote {REPORT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
