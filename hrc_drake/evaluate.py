"""Monte Carlo evaluation of a decider against an operator population, at task level.

A run starts from the empty base: the decider proposes, the operator model answers, each task
takes its time from the cost table (the operator's part scaled by the model's
``bolt_scale(step)``, for `slow`), plus `deviation_seconds` whenever the operator did not perform
the proposal (see `hrc_drake.tasks.deciders`); the run ends in a terminal state, or after
`MAX_TASKS` tasks (not completed). Run i is seeded from (seed, i) and the decider is reset
before it, so runs are independent: serial and ``--workers K`` give the same report.

Times are simulated seconds, so the report does not depend on the machine; wall-clock figures
are under ``wall_*`` keys. Robot idle time at task boundaries is 0 at task level: the cell plans
the predicted tasks ahead while the operator bolts, so a plan is ready at each boundary.
Time figures (mean, p95, worst) are over the completed runs.
"""

from __future__ import annotations

import io
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hrc_drake.hri.populations import make_operator_model
from hrc_drake.paths import UsageError, check_output_path
from hrc_drake.tasks.costs import CostTable, load_cost_table, operator_seconds
from hrc_drake.tasks.deciders import DECIDERS, DEVIATION_SECONDS, make_decider
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.tokens import UNDO

MAX_TASKS = 100


@dataclass(frozen=True)
class RunResult:
    """One run: whether it finished, its simulated seconds, tasks, undos and deviations."""

    completed: bool
    seconds: float
    tasks: int
    undos: int
    deviations: int


def run_seed(seed: int, run: int) -> int:
    """The operator's seed of run `run` of an evaluation seeded `seed`."""
    return int(np.random.SeedSequence([seed, run]).generate_state(1)[0])


def simulate_run(
    space: StateSpace,
    costs: CostTable,
    decider,
    operator,
    deviation_seconds: float = DEVIATION_SECONDS,
    max_tasks: int = MAX_TASKS,
) -> RunResult:
    """Play one run from the empty base (the decider is not reset: it keeps what it learned)."""
    index, seconds, undos, deviations = 0, 0.0, 0, 0
    scale = getattr(operator, "bolt_scale", None)
    for step in range(1, max_tasks + 1):
        if space.kind[index] == StateKind.TERMINAL:
            return RunResult(True, seconds, step - 1, undos, deviations)
        state = space.sequence(index)
        proposal = decider.propose(state)
        performed = operator(step, state, proposal)
        feasible = dict(space.tasks(index))
        if performed not in feasible:
            raise UsageError(
                f"operator model performed {performed!r}, not feasible in {list(state)}; "
                f"feasible: {sorted(feasible)}"
            )
        cost = costs.cost(state, performed)
        seconds += cost.seconds
        if scale is not None:
            factor = scale(step)
            if factor != 1.0:
                part = cost.operator
                if part is None:
                    part = min(cost.seconds, operator_seconds(space.spec, state, performed))
                seconds += (factor - 1.0) * part
        if performed != proposal:
            deviations += 1
            seconds += deviation_seconds
        undos += performed == UNDO
        decider.observe(state, proposal, performed)
        index = feasible[performed]
    done = space.kind[index] == StateKind.TERMINAL
    return RunResult(bool(done), seconds, max_tasks, undos, deviations)


@dataclass(frozen=True)
class Setup:
    """What every worker needs to play runs (picklable)."""

    space: StateSpace
    costs: CostTable
    decider: str
    operator_model: str
    params: dict[str, Any]
    seed: int
    deviation_seconds: float = DEVIATION_SECONDS


_WORKER: dict[str, Any] = {}


def _prepare(setup: Setup) -> None:
    # Built once per process: deciders hold numpy solutions, the paper's agent trains here
    # (seeded, so every process learns the same table).
    _WORKER["setup"] = setup
    _WORKER["decider"] = make_decider(
        setup.decider, setup.space, setup.costs, setup.seed, setup.deviation_seconds
    )


def _play(run: int) -> RunResult:
    setup, decider = _WORKER["setup"], _WORKER["decider"]
    decider.reset()
    operator = make_operator_model(
        setup.operator_model, setup.space, seed=run_seed(setup.seed, run), **setup.params
    )
    return simulate_run(setup.space, setup.costs, decider, operator, setup.deviation_seconds)


def evaluate(setup: Setup, runs: int, workers: int = 1, progress=None) -> dict[str, Any]:
    """Play `runs` runs (over `workers` processes) and summarise them (see `summarise`)."""
    if runs < 1:
        raise UsageError(f"--runs {runs}: give at least 1 run")
    if workers < 1:
        raise UsageError(f"--workers {workers}: give at least 1 worker")
    # Fail fast, in this process, on a bad decider, model or parameter.
    make_operator_model(setup.operator_model, setup.space, seed=0, **setup.params)
    if setup.decider not in DECIDERS:
        make_decider(setup.decider, setup.space, setup.costs)
    start = time.perf_counter()
    if workers == 1:
        _prepare(setup)
        results = []
        for i in range(runs):
            results.append(_play(i))
            if progress is not None:
                progress(i + 1, runs)
    else:
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(workers, initializer=_prepare, initargs=(setup,)) as pool:
            results = pool.map(_play, range(runs), chunksize=max(1, runs // (4 * workers)))
    wall = time.perf_counter() - start
    report = summarise(setup, results)
    report["wall_seconds"] = round(wall, 3)
    report["wall_runs_per_second"] = round(runs / wall, 1) if wall > 0 else None
    report["workers"] = workers
    return report


def summarise(setup: Setup, results: list[RunResult]) -> dict[str, Any]:
    """The JSON report of a list of runs."""
    done = [r for r in results if r.completed]
    times = np.array([r.seconds for r in done])

    def fig(x):
        return None if x is None else round(float(x), 3)

    return {
        "decider": setup.decider,
        "operator_model": setup.operator_model,
        "params": dict(setup.params),
        "assembly": setup.space.spec.name,
        "runs": len(results),
        "completed": len(done),
        "completion_rate": len(done) / len(results),
        "mean_time": fig(times.mean() if len(done) else None),
        "p95_time": fig(np.percentile(times, 95) if len(done) else None),
        "worst_time": fig(times.max() if len(done) else None),
        "mean_tasks": fig(np.mean([r.tasks for r in results])),
        "mean_undos": fig(np.mean([r.undos for r in results])),
        "mean_deviations": fig(np.mean([r.deviations for r in results])),
        "mean_idle": 0.0,
        "deviation_seconds": setup.deviation_seconds,
        "seed": setup.seed,
        "times": [round(r.seconds, 3) for r in done],
    }


def parse_params(items: list[str] | None) -> dict[str, str]:
    """``["p=0.3", "order=S23"]`` -> ``{"p": "0.3", "order": "S23"}``; UsageError otherwise."""
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--param {item!r}: write KEY=VALUE, e.g. --param p=0.3")
        params[key.strip()] = value.strip()
    return params


def plot_times(report: dict[str, Any], path: Path) -> None:
    """Histogram of the completed runs' assembly times (``report["times"]``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hrc_drake.atomic import atomic_write_bytes

    times = report["times"]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.hist(times, bins=30, color="tab:blue")
    ax.set_xlabel("assembly time [s] (simulated)")
    ax.set_ylabel("runs")
    ax.set_title(
        f"{report['decider']} vs {report['operator_model']}: {report['completed']}/"
        f"{report['runs']} completed"
    )
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".").lower())
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def cmd_evaluate(args) -> int:
    """`hrc-drake evaluate`: Monte Carlo runs of a decider against an operator model."""
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    plot = None if args.plot is None else check_output_path(args.plot, "--plot", PLOT_SUFFIXES)
    if args.decider not in DECIDERS:
        raise UsageError(f"unknown decider {args.decider!r}; known deciders: {', '.join(DECIDERS)}")
    space = generate_states(load_spec(args.assembly))
    params = parse_params(args.param)
    make_operator_model(args.operator_model, space, seed=0, **params)
    if args.costs is not None:
        costs = load_cost_table(args.costs, space)
    else:
        from hrc_drake.cell.costs import default_cost_table

        costs = default_cost_table(space)
    setup = Setup(space, costs, args.decider, args.operator_model, params, args.seed)
    if args.json:
        report = evaluate(setup, args.runs, args.workers)
    else:
        from hrc_drake.progress import ProgressLine

        with ProgressLine("evaluate", unit="run") as line:
            report = evaluate(setup, args.runs, args.workers, progress=line.update)
    if plot is not None:
        plot_times(report, plot)
    report.pop("times")
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    for key, value in report.items():
        print(f"{key:22} {value}")
    return 0


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def add_evaluate_parser(add) -> None:
    """Register `evaluate` with `add(name, func, help)` of `hrc_drake.cli.build_parser`."""
    p = add("evaluate", cmd_evaluate, "Monte Carlo: a decider against an operator population")
    p.add_argument("--decider", required=True, help=f"one of {', '.join(DECIDERS)}")
    p.add_argument(
        "--operator-model",
        required=True,
        help="follows, random, habitual, mistake-prone, change-of-mind, slow",
    )
    p.add_argument("--runs", type=int, default=1000)
    p.add_argument("--workers", type=int, default=1, help="local processes")
    p.add_argument("--plot", type=Path, default=None, help="histogram of assembly times")
    p.add_argument("--costs", type=Path, default=None, help="cost table (default: the cell's)")
    p.add_argument(
        "--param", action="append", default=None, help="operator model parameter KEY=VALUE"
    )
