"""Monte Carlo evaluation of a decider against an operator population, at task or cell level.

At task level, a run starts from the empty base and plays the interaction timeline of every
boundary (`hrc_drake.tasks.interaction`): the decider proposes and, in ``anticipate`` mode,
commits to a placement or waits; the operator model answers; its indication comes after a delay
drawn for the interface; the task takes its time from the cost table (the operator's part scaled
by the model's ``bolt_scale(step)``, for `slow`), plus what the interaction adds — the delay when
the robot waited, the re-target or swap of a wrong bet, the wait above the seat when a right bet
arrived before the indication. The run ends in a terminal state, or after `MAX_TASKS` tasks (not
completed but `capped`: an operator who keeps undoing can outlast any cap; at cell level the cap is
the scenario's `run.max_steps`, and a capped run with no collision is no failure). Run i is seeded
from (seed, i) (the operator, and the delays in their own stream) and the decider is reset before
it, so runs are independent: serial and ``--workers K`` give the same report. With
`Setup.keep_model` the decider keeps its operator model across the runs (one operator, many
assemblies): runs then follow each other in one process.

Times are simulated seconds, so the report does not depend on the machine; wall-clock figures
are under ``wall_*`` keys. Robot idle time at a task boundary: while the operator bolts, the cell
plans the tasks the decider predicts (`predicted_tasks`: the proposal, and with an operator model
its likely answers); at task level a boundary whose task was among them costs no idle time, any
other the motion layer's median planning time (`PLANNING_SECONDS`).
Time figures (mean, p95, worst) are over the completed runs.

At cell level (``--cell``) each run is a closed-loop simulation of the physical cell: times are the
cell's simulated seconds, and so is the robot's idle time at a boundary (simulated time stands still
while the planner works, so it is one controller update); the wall time it waited for the planner
after the operator's answer is ``wall_mean_idle`` (``plan_ready_rate``: the share of boundaries
whose plan was made ahead, while the operator bolted). A cell run plays the evaluation's
interaction: its Supervisor asks the decider's bet (`commit`) at each boundary and starts on it, or
waits; the simulated operator indicates after the interface's delay (`DelayedIndications`), drawn
from the same seeded stream as the task level's, so a run's delays are the same at both levels. This
module does not know the cell: `Setup.cell` is an object that plays cell runs (`CellRuns`;
`hrc_drake.cell.run.evaluate.CellOptions`), so the dependency goes one way, from the cell to here.
The command line is `hrc_drake.cli.evaluate`.

Runs spread over local processes (``workers``) or, with ``ray``, over a Ray cluster (the optional
extra ``hrc_drake[ray]``): each worker builds its own decider (and, at cell level, its own
diagram per run), and results are gathered by run index, so the report is the same whichever
way it runs (but for the ``wall_*`` figures).

Here are the run loop (`simulate_run`) and the workers that play the runs; what they pass on
(`Setup`, `CellRuns`, `RunResult`, `run_seed`) is `hrc_drake.evaluation_runs`, and the report
of the runs (`summarise`) and its plots are `hrc_drake.evaluation_report`.
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hrc_drake.evaluation_report import summarise
from hrc_drake.evaluation_runs import RunResult, Setup, run_seed
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.paths import UsageError
from hrc_drake.tasks.costs import CostTable, operator_seconds
from hrc_drake.tasks.deciders import DECIDERS, commit_to_proposal, make_decider
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.interaction import (
    Interaction,
    InteractionCosts,
    delay_generator,
)
from hrc_drake.tasks.protocols import Commits, HasOperatorModel, TiresAlongTheRun
from hrc_drake.tasks.tokens import UNDO

MAX_TASKS = 100
# Seconds the robot stands idle at a boundary whose task was not planned ahead: the motion
# layer's median planning time per task (benchmarks/reports/motion.md).
PLANNING_SECONDS = 0.21
# Planning ahead: the answers an operator model expects with at least this probability, most
# likely first, at most this many per boundary (each plan takes ~0.2 s of the ~5 s of bolting).
PREDICT_PROBABILITY = 0.1
PREDICT_AT_MOST = 3


def predicted_tasks(decider, state: tuple[str, ...], proposal: str) -> list[str]:
    """What to plan ahead for `state`: the tasks the operator may perform, most likely first —
    the proposal, and with an operator model (`mpc`) every answer it expects with probability
    >= `PREDICT_PROBABILITY` (at most `PREDICT_AT_MOST`)."""
    model = decider.model if isinstance(decider, HasOperatorModel) else None
    if model is None:
        return [proposal]
    probs = model.outcome_probabilities(tuple(state), proposal)
    ranked = sorted(probs, key=lambda t: (-probs[t], t != proposal, t))
    return [t for t in ranked if probs[t] >= PREDICT_PROBABILITY][:PREDICT_AT_MOST]


def commitment(decider, state: tuple[str, ...], proposal: str, interaction: Interaction):
    """What the decider starts on before the indication (None: the robot waits): its own
    choice (`commit`), or for a decider without one its proposal; always None in ``wait``."""
    if not interaction.anticipates:
        return None
    if not isinstance(decider, Commits):
        return commit_to_proposal(interaction, proposal)
    return decider.commit(state, proposal)


@dataclass
class _Tally:
    """What a run counts as it goes."""

    seconds: float = 0.0
    undos: int = 0
    deviations: int = 0
    commits: int = 0
    retargets: int = 0
    swaps: int = 0
    delay: float = 0.0
    wait: float = 0.0

    def result(self, done: bool, tasks: int, ready: list[bool], capped=False) -> RunResult:
        # Idle at a boundary: none when the task was planned ahead, else the planning time.
        idle = tuple(0.0 if r else PLANNING_SECONDS for r in ready)
        return RunResult(
            bool(done), self.seconds, tasks, self.undos, self.deviations, idle, tuple(ready),
            commits=self.commits, retargets=self.retargets, swaps=self.swaps,
            indication_delay=self.delay, indication_wait=self.wait, capped=capped,
        )  # fmt: skip


def simulate_run(
    space: StateSpace,
    costs: CostTable,
    decider,
    operator,
    timeline: InteractionCosts | None = None,
    delays: np.random.Generator | None = None,
    max_tasks: int = MAX_TASKS,
) -> RunResult:
    """Play one run from the empty base (the decider is not reset: it keeps what it learned).

    `timeline` prices the interaction (default: `InteractionCosts` of the default interaction,
    anticipate over the pointer); `delays` draws the indication delays (default: seeded 0)."""
    timeline = timeline or InteractionCosts(space, costs, Interaction())
    delays = delays if delays is not None else delay_generator(0)
    index, tally = 0, _Tally()
    ready: list[bool] = []
    scale = operator.bolt_scale if isinstance(operator, TiresAlongTheRun) else None
    for step in range(1, max_tasks + 1):
        if space.kind[index] == StateKind.TERMINAL:
            return tally.result(True, step - 1, ready)
        state = space.sequence(index)
        proposal = decider.propose(state)
        committed = commitment(decider, state, proposal, timeline.interaction)
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
        tally.seconds += cost.seconds
        if scale is not None:
            factor = scale(step)
            if factor != 1.0:
                part = cost.operator
                if part is None:
                    part = min(cost.seconds, operator_seconds(space.spec, state, performed))
                tally.seconds += (factor - 1.0) * part
        _interaction(tally, timeline, state, committed, performed, delays)
        tally.deviations += performed != proposal
        tally.undos += performed == UNDO
        decider.observe(state, proposal, performed)
        index = feasible[performed]
    done = space.kind[index] == StateKind.TERMINAL
    return tally.result(done, max_tasks, ready, capped=not done)


def _interaction(tally: _Tally, timeline, state, committed, performed, delays) -> None:
    """Add one boundary's interaction to the run's tally."""
    step = timeline.play(state, committed, performed, timeline.interaction.delay.sample(delays))
    tally.seconds += step.seconds
    tally.delay += step.delay
    tally.commits += step.committed is not None  # none on a task the robot cannot plan
    tally.retargets += step.retargeted
    tally.swaps += step.swapped
    if step.committed is None:
        tally.wait += step.delay
    elif not (step.retargeted or step.swapped):
        tally.wait += step.seconds  # a right bet waits only for the rest of the delay


_WORKER: dict[str, Any] = {}


class _CtrlC:
    """Ctrl-C noted as well as raised: SIGINT raises KeyboardInterrupt where the main thread
    happens to be, and one raised inside a finalizer or a callback is printed and dropped
    ("Exception ignored in ..."; seen once in a million-run evaluation under load, which then
    ran on). The loops also check `pressed` between runs. Outside the main thread nothing is
    installed (Python delivers signals to it only)."""

    def __init__(self):
        self.pressed = False
        self._previous = None

    def __enter__(self) -> _CtrlC:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame):
        self.pressed = True
        raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def _prepare_worker(setup: Setup) -> None:
    # A pool's worker leaves Ctrl-C to the parent, which terminates the pool: the terminal
    # sends SIGINT to the whole process group, and a worker's KeyboardInterrupt would only
    # print its traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _prepare(setup)


def _prepare(setup: Setup) -> None:
    # Built once per process: deciders hold numpy solutions, the paper's agent trains here
    # (seeded, so every process learns the same table).
    _WORKER["setup"] = setup
    _WORKER["decider"] = make_decider(
        setup.decider, setup.space, setup.costs, setup.seed, setup.interaction, setup.model
    )
    _WORKER["timeline"] = InteractionCosts(setup.space, setup.costs, setup.interaction)
    if setup.cell is not None:
        _WORKER["cell"] = setup.cell.prepare(setup.space)


def _play(run: int) -> RunResult:
    setup, decider = _WORKER["setup"], _WORKER["decider"]
    if setup.keep_model and run > 0:
        decider.start_run()
    else:
        decider.reset()
    if setup.cell is not None:
        # The run's scenario builds the operator (`CellOptions.run_text`): the model seeded
        # `run_seed`, indicating after the delays the task level draws for the same run.
        return setup.cell.play(_WORKER["cell"], setup, decider, run)
    seed = run_seed(setup.seed, run)
    operator = make_operator_model(setup.operator_model, setup.space, seed=seed, **setup.params)
    delays = delay_generator(setup.seed, run)
    return simulate_run(setup.space, setup.costs, decider, operator, _WORKER["timeline"], delays)


def _play_many(runs: list[int]) -> list[RunResult]:
    return [_play(i) for i in runs]


def _play_chunk(runs: list[int]) -> tuple[list[int], list[RunResult]]:
    return runs, _play_many(runs)


class _RayWorker:
    """A Ray actor: prepares once (its own decider; cell runs build their own diagrams)."""

    def __init__(self, setup: Setup):
        _prepare(setup)

    def play(self, runs: list[int]) -> list[RunResult]:
        return _play_many(runs)


def _chunks(runs: int, workers: int, per_worker: int = 4) -> list[list[int]]:
    """Run indices in contiguous chunks, about `per_worker` per worker (`per_worker` 0: one run
    per chunk, for long runs such as the cell's, so that progress shows every run)."""
    if per_worker == 0:
        return [[i] for i in range(runs)]
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
        chunks = _chunks(runs, workers, 0 if setup.cell is not None else 4)
        pending = {actors[k % workers].play.remote(chunk): chunk for k, chunk in enumerate(chunks)}
        results: list[RunResult | None] = [None] * runs
        done = 0
        try:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                chunk = pending.pop(ready[0])
                for i, result in zip(chunk, ray.get(ready[0]), strict=True):
                    results[i] = result
                done += len(chunk)
                if progress is not None:
                    progress(done, runs)
        except KeyboardInterrupt:
            return results, workers, True  # shutting Ray down below ends its actors
        return results, workers, False
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
    setup = _checked_setup(setup, runs, workers, ray)
    start = time.perf_counter()
    results: list[RunResult | None] = [None] * runs
    if ray:
        results, workers, interrupted = _run_ray(setup, runs, workers, ray_address, progress)
        backend = "ray"
    elif workers in (None, 1):
        workers, backend = 1, "serial"
        interrupted = _run_serial(setup, runs, results, progress)
    else:
        backend = "processes"
        interrupted = _run_pool(setup, runs, workers, results, progress)
    wall = time.perf_counter() - start
    indices = [i for i, r in enumerate(results) if r is not None]
    report = summarise(setup, [results[i] for i in indices], indices)
    # Ctrl-C: the report is of the runs done (`runs`), out of those asked for.
    report["interrupted"] = interrupted
    report["runs_requested"] = runs
    report["wall_seconds"] = round(wall, 3)
    report["wall_runs_per_second"] = round(len(indices) / wall, 3) if wall > 0 else None
    report["workers"] = workers
    report["backend"] = backend
    return report


def _checked_setup(setup: Setup, runs: int, workers: int | None, ray: bool) -> Setup:
    """The setup the runs play (at cell level, the cell playing the evaluation's interaction),
    once checked in this process: UsageError for the runs and workers asked for, and whatever
    a bad decider, operator model, parameter, cost table or cell raises, before any run."""
    if runs < 1:
        raise UsageError(f"--runs {runs}: give at least 1 run")
    if workers is not None and workers < 1:
        raise UsageError(f"--workers {workers}: give at least 1 worker")
    if setup.keep_model and (ray or workers not in (None, 1)):
        raise UsageError(
            "--keep-model: one operator's assemblies follow each other, each learning from the "
            "last; they run in one process: drop --workers and --ray"
        )
    if setup.cell is not None:
        # The cell plays the interaction the deciders price.
        setup = replace(setup, cell=setup.cell.playing(setup.interaction.mode))
    # Fail fast, in this process, on a bad decider, model, parameter or cost table.
    operator = make_operator_model(setup.operator_model, setup.space, seed=0, **setup.params)
    if setup.decider not in DECIDERS:
        make_decider(setup.decider, setup.space, setup.costs)
    InteractionCosts(setup.space, setup.costs, setup.interaction)
    if setup.cell is not None:
        setup.cell.check(operator, setup.operator_model)
        setup.cell.prepare(setup.space)
    return setup


def _run_serial(setup: Setup, runs: int, results: list, progress) -> bool:
    """Play the runs one after the other in this process into `results` (by run index); True
    if Ctrl-C stopped them first."""
    _prepare(setup)
    interrupted = False
    with _CtrlC() as ctrl_c:
        try:
            for i in range(runs):
                results[i] = _play(i)
                if progress is not None:
                    progress(i + 1, runs)
                if ctrl_c.pressed:
                    raise KeyboardInterrupt
        except KeyboardInterrupt:
            interrupted = True
    return interrupted


def _run_pool(setup: Setup, runs: int, workers: int, results: list, progress) -> bool:
    """Play the runs over `workers` local processes into `results` (by run index); True if
    Ctrl-C stopped them first (the workers are terminated: none is left running)."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    chunks = _chunks(runs, workers, 0 if setup.cell is not None else 4)
    done = 0
    pool = ctx.Pool(workers, initializer=_prepare_worker, initargs=(setup,))
    try:
        with _CtrlC() as ctrl_c:
            # Unordered: progress counts every finished chunk, not the longest prefix of them.
            for indices, chunk in pool.imap_unordered(_play_chunk, chunks):
                for i, result in zip(indices, chunk, strict=True):
                    results[i] = result
                done += len(chunk)
                if progress is not None:
                    progress(done, runs)
                if ctrl_c.pressed:
                    raise KeyboardInterrupt
    except KeyboardInterrupt:
        return True
    finally:
        # Terminated, not closed: on Ctrl-C the workers are mid-run (SIGTERM ends them); after
        # the last chunk they are idle. join() waits until every one has exited.
        pool.terminate()
        pool.join()
    return False
