"""Monte Carlo evaluation of a decider against an operator population, at task or cell level.

At task level, a run starts from the empty base: the decider proposes, the operator model
answers, each task takes its time from the cost table (the operator's part scaled by the model's
``bolt_scale(step)``, for `slow`), plus `deviation_seconds` whenever the operator did not perform
the proposal (see `hrc_drake.tasks.deciders`); the run ends in a terminal state, or after
`MAX_TASKS` tasks (not completed). Run i is seeded from (seed, i) and the decider is reset
before it, so runs are independent: serial and ``--workers K`` give the same report.

Times are simulated seconds, so the report does not depend on the machine; wall-clock figures
are under ``wall_*`` keys. Robot idle time at a task boundary: while the operator bolts, the cell
plans the tasks the decider predicts (`predicted_tasks`: the proposal, and with an operator model
its likely answers); at task level a boundary whose task was among them costs no idle time, any
other the motion layer's median planning time (`PLANNING_SECONDS`).
Time figures (mean, p95, worst) are over the completed runs.

At cell level (``--cell``, `hrc_drake.cell.evaluate`) each run is a closed-loop simulation of the
physical cell: times are the cell's simulated seconds, and the robot's idle time at a boundary is
the wall time it waited for the planner after the operator's answer (``plan_ready_rate``: the
share of boundaries whose plan was made ahead, while the operator bolted).

Runs spread over local processes (``workers``) or, with ``ray``, over a Ray cluster (the optional
extra ``hrc_drake[ray]``): each worker builds its own decider (and, at cell level, its own
diagram per run), and results are gathered by run index, so the report is the same whichever
way it runs (but for the ``wall_*`` figures and, at cell level, the measured idle time).
"""

from __future__ import annotations

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
# Seconds the robot stands idle at a boundary whose task was not planned ahead: the motion
# layer's median planning time per task (benchmarks/reports/motion.md).
PLANNING_SECONDS = 0.21
# Planning ahead: the answers an operator model expects with at least this probability, most
# likely first, at most this many per boundary (each plan takes ~0.2 s of the ~5 s of bolting).
PREDICT_PROBABILITY = 0.1
PREDICT_AT_MOST = 3


@dataclass(frozen=True)
class RunResult:
    """One run: whether it finished, its simulated seconds, tasks, undos and deviations, the
    robot's idle seconds and whether the plan was ready, per boundary; at cell level also the
    run's error and its robot collisions."""

    completed: bool
    seconds: float
    tasks: int
    undos: int
    deviations: int
    idle: tuple[float, ...] = ()
    plan_ready: tuple[bool, ...] = ()
    error: str | None = None
    collisions: int = 0


def run_seed(seed: int, run: int) -> int:
    """The operator's seed of run `run` of an evaluation seeded `seed`."""
    return int(np.random.SeedSequence([seed, run]).generate_state(1)[0])


def predicted_tasks(decider, state: tuple[str, ...], proposal: str) -> list[str]:
    """What to plan ahead for `state`: the tasks the operator may perform, most likely first —
    the proposal, and with an operator model (`mpc`) every answer it expects with probability
    >= `PREDICT_PROBABILITY` (at most `PREDICT_AT_MOST`)."""
    model = getattr(decider, "model", None)
    if model is None:
        return [proposal]
    probs = model.outcome_probabilities(tuple(state), proposal)
    ranked = sorted(probs, key=lambda t: (-probs[t], t != proposal, t))
    return [t for t in ranked if probs[t] >= PREDICT_PROBABILITY][:PREDICT_AT_MOST]


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
    ready: list[bool] = []
    scale = getattr(operator, "bolt_scale", None)
    for step in range(1, max_tasks + 1):
        if space.kind[index] == StateKind.TERMINAL:
            return _task_result(True, seconds, step - 1, undos, deviations, ready)
        state = space.sequence(index)
        proposal = decider.propose(state)
        planned = predicted_tasks(decider, state, proposal)
        performed = operator(step, state, proposal)
        ready.append(performed in planned)
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
    return _task_result(bool(done), seconds, max_tasks, undos, deviations, ready)


def _task_result(done, seconds, tasks, undos, deviations, ready: list[bool]) -> RunResult:
    # Idle at a boundary: none when the task was planned ahead, else the planning time.
    idle = tuple(0.0 if r else PLANNING_SECONDS for r in ready)
    return RunResult(done, seconds, tasks, undos, deviations, idle, tuple(ready))


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
    cell: Any = None
    """None: task level; an `hrc_drake.cell.evaluate.CellOptions`: runs through the cell."""


_WORKER: dict[str, Any] = {}


def _prepare(setup: Setup) -> None:
    # Built once per process: deciders hold numpy solutions, the paper's agent trains here
    # (seeded, so every process learns the same table).
    _WORKER["setup"] = setup
    _WORKER["decider"] = make_decider(
        setup.decider, setup.space, setup.costs, setup.seed, setup.deviation_seconds
    )
    if setup.cell is not None:
        from hrc_drake.cell.evaluate import evaluation_scenario

        _WORKER["scenario"] = evaluation_scenario(setup.cell, setup.space.spec)


def _play(run: int) -> RunResult:
    setup, decider = _WORKER["setup"], _WORKER["decider"]
    decider.reset()
    operator = make_operator_model(
        setup.operator_model, setup.space, seed=run_seed(setup.seed, run), **setup.params
    )
    if setup.cell is not None:
        from hrc_drake.cell.evaluate import play_cell_run

        return play_cell_run(_WORKER["scenario"], setup.space, decider, operator)
    return simulate_run(setup.space, setup.costs, decider, operator, setup.deviation_seconds)


def _play_many(runs: list[int]) -> list[RunResult]:
    return [_play(i) for i in runs]


class _RayWorker:
    """A Ray actor: prepares once (its own decider; cell runs build their own diagrams)."""

    def __init__(self, setup: Setup):
        _prepare(setup)

    def play(self, runs: list[int]) -> list[RunResult]:
        return _play_many(runs)


def _chunks(runs: int, workers: int, per_worker: int = 4) -> list[list[int]]:
    """Run indices in contiguous chunks, about `per_worker` per worker."""
    size = max(1, -(-runs // (per_worker * workers)))
    return [list(range(i, min(i + size, runs))) for i in range(0, runs, size)]


def _check_reachable(address: str | None, timeout: float = 3.0) -> None:
    """UsageError unless a ``host:port`` (or ``ray://host:port``) address answers: Ray itself
    waits minutes for a cluster that is not there."""
    if not address or address == "auto":
        return
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        raise UsageError(
            f"--ray {address}: give the cluster's address as HOST:PORT (e.g. 10.0.0.5:6379, "
            "as `ray start --head` prints it), or no address for a local cluster"
        )
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as err:
        raise UsageError(
            f"--ray {address}: no Ray cluster answers there ({err}); start one with "
            "`ray start --head` or give no address for a local cluster"
        ) from None


def _run_ray(setup: Setup, runs: int, workers: int | None, address: str | None, progress):
    try:
        import ray
    except ImportError:
        raise UsageError(
            "--ray needs Ray, which is not installed: pip install 'hrc_drake[ray]'"
        ) from None
    started = not ray.is_initialized()
    if started:
        import logging

        _check_reachable(address)

        try:
            ray.init(
                address=address or None,
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.WARNING,
            )
        except (ConnectionError, RuntimeError, ValueError) as err:
            where = address or "a local Ray instance"
            raise UsageError(
                f"--ray {address or ''}: cannot start or reach {where}: {err}; give the address "
                "of a running cluster (ray start --head prints it), or no address for a local one"
            ) from None
    try:
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        actor = ray.remote(num_cpus=1)(_RayWorker)
        actors = [actor.remote(setup) for _ in range(workers)]
        chunks = _chunks(runs, workers)
        pending = {actors[k % workers].play.remote(chunk): chunk for k, chunk in enumerate(chunks)}
        results: list[RunResult | None] = [None] * runs
        done = 0
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            chunk = pending.pop(ready[0])
            for i, result in zip(chunk, ray.get(ready[0]), strict=True):
                results[i] = result
            done += len(chunk)
            if progress is not None:
                progress(done, runs)
        return results, workers
    finally:
        if started:
            ray.shutdown()


def evaluate(
    setup: Setup,
    runs: int,
    workers: int | None = 1,
    progress=None,
    ray: bool = False,
    ray_address: str | None = None,
) -> dict[str, Any]:
    """Play `runs` runs and summarise them (see `summarise`): in this process (`workers` 1),
    over `workers` local processes, or with `ray` on a Ray cluster (`ray_address`; None: a
    local one) over `workers` actors (None: one per CPU of the cluster)."""
    if runs < 1:
        raise UsageError(f"--runs {runs}: give at least 1 run")
    if workers is not None and workers < 1:
        raise UsageError(f"--workers {workers}: give at least 1 worker")
    # Fail fast, in this process, on a bad decider, model or parameter.
    operator = make_operator_model(setup.operator_model, setup.space, seed=0, **setup.params)
    if setup.decider not in DECIDERS:
        make_decider(setup.decider, setup.space, setup.costs)
    if setup.cell is not None:
        from hrc_drake.cell.evaluate import check_cell_operator, evaluation_scenario

        check_cell_operator(operator, setup.operator_model)
        evaluation_scenario(setup.cell, setup.space.spec)
    start = time.perf_counter()
    if ray:
        results, workers = _run_ray(setup, runs, workers, ray_address, progress)
        backend = "ray"
    elif workers in (None, 1):
        workers, backend = 1, "serial"
        _prepare(setup)
        results = []
        for i in range(runs):
            results.append(_play(i))
            if progress is not None:
                progress(i + 1, runs)
    else:
        import multiprocessing

        backend = "processes"
        ctx = multiprocessing.get_context("spawn")
        chunks = _chunks(runs, workers)
        results = []
        with ctx.Pool(workers, initializer=_prepare, initargs=(setup,)) as pool:
            for chunk in pool.imap(_play_many, chunks):
                results.extend(chunk)
                if progress is not None:
                    progress(len(results), runs)
    wall = time.perf_counter() - start
    report = summarise(setup, results)
    report["wall_seconds"] = round(wall, 3)
    report["wall_runs_per_second"] = round(runs / wall, 3) if wall > 0 else None
    report["workers"] = workers
    report["backend"] = backend
    return report


def summarise(setup: Setup, results: list[RunResult]) -> dict[str, Any]:
    """The JSON report of a list of runs."""
    done = [r for r in results if r.completed]
    times = np.array([r.seconds for r in done])
    idle = [x for r in results for x in r.idle]
    ready = [x for r in results for x in r.plan_ready]

    def fig(x):
        return None if x is None else round(float(x), 3)

    report = {
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
        "mean_idle": round(float(np.mean(idle)), 4) if idle else 0.0,
        "p95_idle": round(float(np.percentile(idle, 95)), 4) if idle else 0.0,
        "plan_ready_rate": round(float(np.mean(ready)), 4) if ready else None,
        "deviation_seconds": setup.deviation_seconds,
        "seed": setup.seed,
        "level": "task" if setup.cell is None else "cell",
        "times": [round(r.seconds, 3) for r in done],
    }
    if setup.cell is not None:
        errors = sorted({r.error for r in results if r.error and not r.completed})
        report.update(
            {
                # The cell's robot waits for the answer before it moves: no deviation time.
                "deviation_seconds": 0.0,
                "collisions": int(sum(r.collisions for r in results)),
                "scenario": setup.cell.scenario,
                "errors": errors[:5],
            }
        )
    return report


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


def cmd_evaluate(args) -> int:
    """`hrc-drake evaluate`: Monte Carlo runs of a decider against an operator model."""
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    plot = None
    if args.plot is not None:
        from hrc_drake.tasks.plots import FORMATS

        plot = check_output_path(args.plot, "--plot", FORMATS)
    if args.decider not in DECIDERS:
        raise UsageError(f"unknown decider {args.decider!r}; known deciders: {', '.join(DECIDERS)}")
    unused = ["--gamma"] if args.gamma is not None else []
    if args.mistake_prob != 0.05:  # the common option's default
        unused.append("--mistake-prob")
    if unused:
        raise UsageError(
            f"{', '.join(unused)}: not used by evaluate (each decider has its own model); set "
            "the operator population's parameters with --param, e.g. --param p=0.3"
        )
    cell_only = [f for f, v in (("--lean", args.lean), ("--scenario", args.scenario)) if v]
    if args.scenario_text:
        cell_only.append("--scenario-text")
    if cell_only and not args.cell:
        raise UsageError(f"{', '.join(cell_only)}: only for runs through the cell; add --cell")
    space = generate_states(load_spec(args.assembly))
    params = parse_params(args.param)
    make_operator_model(args.operator_model, space, seed=0, **params)
    cell = None
    if args.cell:
        from hrc_drake.cell.evaluate import DEFAULT_BASE_SCENARIO, CellOptions
        from hrc_drake.cell.scenario import LEAN

        overrides = [t for t in (LEAN if args.lean else None, *(args.scenario_text or [])) if t]
        cell = CellOptions(args.scenario or DEFAULT_BASE_SCENARIO, tuple(overrides))
    runs = args.runs if args.runs is not None else (DEFAULT_CELL_RUNS if cell else DEFAULT_RUNS)
    if args.costs is not None:
        costs = load_cost_table(args.costs, space)
    else:
        from hrc_drake.cell.costs import default_cost_table

        costs = default_cost_table(space)
    setup = Setup(space, costs, args.decider, args.operator_model, params, args.seed, cell=cell)
    from hrc_drake.progress import ProgressLine

    misfits: tuple[type[Exception], ...] = ()  # none at task level (which needs no Drake)
    if cell is not None:
        from hrc_drake.cell_models import CellModelError

        misfits = (CellModelError,)

    level = "cell" if cell else "evaluate"
    with ProgressLine(f"{level} {args.decider} vs {args.operator_model}", unit="run") as line:
        try:
            report = evaluate(
                setup,
                runs,
                args.workers,
                progress=line.update,
                ray=args.ray is not None,
                ray_address=args.ray or None,
            )
        except misfits as err:
            raise UsageError(str(err)) from None
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


DEFAULT_RUNS = 1000
DEFAULT_CELL_RUNS = 20


def add_evaluate_parser(add) -> None:
    """Register `evaluate` with `add(name, func, help)` of `hrc_drake.cli.build_parser`."""
    p = add("evaluate", cmd_evaluate, "Monte Carlo: a decider against an operator population")
    p.add_argument("--decider", required=True, help=f"one of {', '.join(DECIDERS)}")
    p.add_argument(
        "--operator-model",
        required=True,
        help="follows, random, habitual, mistake-prone, change-of-mind, slow",
    )
    p.add_argument(
        "--runs",
        type=int,
        default=None,
        help=f"runs (default {DEFAULT_RUNS}; with --cell {DEFAULT_CELL_RUNS})",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="local processes (default 1); with --ray, Ray actors (default one per CPU)",
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=None,
        metavar="ADDRESS",
        help="spread the runs on a Ray cluster at ADDRESS (no address: a local one); needs the "
        "extra hrc_drake[ray]",
    )
    p.add_argument(
        "--cell",
        action="store_true",
        help="run through the physical cell (closed-loop simulations; dozens, not thousands)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        help="with --cell: the base scenario (default row1-optimal; its operator is replaced)",
    )
    p.add_argument("--lean", action="store_true", help="with --cell: short holds (tests)")
    p.add_argument(
        "--scenario-text",
        action="append",
        default=None,
        help="with --cell: YAML overrides of the base scenario",
    )
    p.add_argument("--plot", type=Path, default=None, help="histogram of assembly times")
    p.add_argument("--costs", type=Path, default=None, help="cost table (default: the cell's)")
    p.add_argument(
        "--param", action="append", default=None, help="operator model parameter KEY=VALUE"
    )
