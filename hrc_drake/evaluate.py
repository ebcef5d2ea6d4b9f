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
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

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
from hrc_drake.tasks.operator_model import OnlineOperatorModel
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


@dataclass(frozen=True)
class RunResult:
    """One run: whether it finished, its simulated seconds, tasks, undos and deviations, the
    robot's idle seconds and whether the plan was ready, per boundary; at cell level also the
    run's error and its robot collisions. The interaction: boundaries where the robot started on
    its prediction (`commits`), re-targeted and swapped; the indication delays drawn
    (`indication_delay`, summed) and the seconds the robot stood waiting for an indication
    (`indication_wait`: the whole delay when it waited, the rest of it when a right bet reached
    the seat first)."""

    completed: bool
    seconds: float
    tasks: int
    undos: int
    deviations: int
    idle: tuple[float, ...] = ()
    plan_ready: tuple[bool, ...] = ()
    error: str | None = None
    collisions: int = 0
    commits: int = 0
    retargets: int = 0
    swaps: int = 0
    indication_delay: float = 0.0
    indication_wait: float = 0.0
    wall_idle: tuple[float, ...] = ()  # cell level: the idle waits in wall-clock seconds
    states: tuple[str, ...] = ()
    """Cell only: the states the run went through (their names)."""
    violations: int = 0
    """Cell only: separation violations (ISO/TS 15066 S_p; 0 without the operator's body)."""
    handovers: int = 0
    """Cell only: tasks the robot handed over and the operator did by hand."""
    capped: bool = False
    """Ended by the run's own task cap (not terminal, no failure: an operator who keeps undoing
    can outlast any cap)."""


def run_seed(seed: int, run: int) -> int:
    """The operator's seed of run `run` of an evaluation seeded `seed`."""
    return int(np.random.SeedSequence([seed, run]).generate_state(1)[0])


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
    tally.commits += committed is not None
    tally.retargets += step.retargeted
    tally.swaps += step.swapped
    if committed is None:
        tally.wait += step.delay
    elif not (step.retargeted or step.swapped):
        tally.wait += step.seconds  # a right bet waits only for the rest of the delay


class CellRuns(Protocol):
    """What plays runs through the physical cell (picklable: it travels to every worker)."""

    def prepare(self, space: StateSpace) -> Any:
        """What every run of a worker shares (the scenario); errors here are the user's input."""

    def check(self, operator, model_name: str) -> None:
        """UsageError for an operator model the cell cannot play."""

    def play(self, prepared: Any, setup: Setup, decider, run: int) -> RunResult:
        """Run `run` of the evaluation `setup`; the decider is not reset."""

    def replay(self, setup: Setup, run: int) -> str | None:
        """The command that plays run `run` alone (None: it cannot be played alone)."""

    def playing(self, mode: str) -> CellRuns:
        """The same cell playing the interaction `mode` (`anticipate`, `wait`)."""

    def describe(self, space: StateSpace) -> dict[str, Any]:
        """The report's keys naming what ran (the scenario, its overrides)."""


@dataclass(frozen=True)
class Setup:
    """What every worker needs to play runs (picklable)."""

    space: StateSpace
    costs: CostTable
    decider: str
    operator_model: str
    params: dict[str, Any]
    seed: int
    interaction: Interaction = field(default_factory=Interaction)
    keep_model: bool = False
    """One operator, many assemblies: the decider keeps its operator model across the runs
    (`start_run` instead of `reset`), so the runs follow each other in one process."""
    model: OnlineOperatorModel | None = None
    """An operator profile's model for `mpc` to start from (None: a fresh one)."""
    cell: CellRuns | None = None
    """None: task level; else runs through the cell (`hrc_drake.cell.run.evaluate.CellOptions`)."""


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
    start = time.perf_counter()
    results: list[RunResult | None] = [None] * runs
    interrupted = False
    if ray:
        results, workers, interrupted = _run_ray(setup, runs, workers, ray_address, progress)
        backend = "ray"
    elif workers in (None, 1):
        workers, backend = 1, "serial"
        _prepare(setup)
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


def summarise(
    setup: Setup, results: list[RunResult], runs: list[int] | None = None
) -> dict[str, Any]:
    """The JSON report of a list of runs; `runs` are their indices in the evaluation (default
    0, 1, ...: every run, in order), which name the failing ones at cell level."""
    runs = list(range(len(results))) if runs is None else runs
    done = [r for r in results if r.completed]
    times = np.array([r.seconds for r in done])
    idle = [x for r in results for x in r.idle]
    ready = [x for r in results for x in r.plan_ready]

    def fig(x):
        return None if x is None else round(float(x), 3)

    def mean(values):
        # None, not NaN, when Ctrl-C came before any run finished.
        return fig(np.mean(values)) if values else None

    boundaries = sum(r.tasks for r in results)
    interaction = setup.interaction
    report = {
        "decider": setup.decider,
        "operator_model": setup.operator_model,
        "params": dict(setup.params),
        "assembly": setup.space.spec.name,
        "runs": len(results),
        "completed": len(done),
        "completion_rate": len(done) / len(results) if results else None,
        # Not terminal, ended by the run's own task cap with that reason (not a failure).
        "capped": sum(r.capped for r in results),
        "mean_time": fig(times.mean() if len(done) else None),
        "p95_time": fig(np.percentile(times, 95) if len(done) else None),
        "worst_time": fig(times.max() if len(done) else None),
        "mean_tasks": mean([r.tasks for r in results]),
        "mean_undos": mean([r.undos for r in results]),
        "mean_deviations": mean([r.deviations for r in results]),
        "mean_idle": round(float(np.mean(idle)), 4) if idle else 0.0,
        "p95_idle": round(float(np.percentile(idle, 95)), 4) if idle else 0.0,
        "plan_ready_rate": round(float(np.mean(ready)), 4) if ready else None,
        "interaction": interaction.mode,
        "interface": interaction.interface,
        "indication_delay": interaction.delay.to_json(),
        "commit_rate": round(sum(r.commits for r in results) / boundaries, 4)
        if boundaries
        else 0.0,
        "mean_retargets": mean([r.retargets for r in results]),
        "mean_swaps": mean([r.swaps for r in results]),
        "mean_indication_delay": mean([r.indication_delay for r in results]),
        "mean_indication_wait": mean([r.indication_wait for r in results]),
        "keep_model": setup.keep_model,
        "seed": setup.seed,
        "level": "task" if setup.cell is None else "cell",
        "times": [round(r.seconds, 3) for r in done],
    }
    if setup.cell is not None:
        errors = sorted({r.error for r in results if r.error and not (r.completed or r.capped)})
        wall_idle = [x for r in results for x in r.wall_idle]
        report.update(
            {
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
        )
    return report


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
    if result.violations:
        problems.append(f"{result.violations} separation violation(s)")
    return ", ".join(problems)


def failures(setup: Setup, results: list[RunResult], runs: list[int]) -> list[dict[str, Any]]:
    """The cell runs that did not complete or had robot collisions or separation violations,
    each with what replays it alone (`CellRuns.replay`): its index, the operator's seed, model
    and parameters, the stop reason, the states it went through and the command."""
    out = []
    for run, r in zip(runs, results, strict=True):
        if (r.completed or r.capped) and not r.collisions and not r.violations:
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


def plot_decider_means(
    reports: dict[tuple[str, str], dict[str, Any]],
    deciders: list[str],
    models: list[str],
    path: Path,
    title: str,
) -> None:
    """Mean and p95 assembly time of each decider, one panel per operator model (columns) and
    figure (rows: mean, p95), on linear axes fitted to each panel: the deciders differ by
    fractions of a second within a population and by tens of seconds across populations, so a
    shared axis (or a log one) would hide the differences that matter. Every value is printed
    beside its dot. `reports[decider, model]` is a `summarise` report."""
    from matplotlib.ticker import MaxNLocator

    from hrc_drake.tasks.plots import plt, save_figure

    rows = (("mean_time", "mean [s]"), ("p95_time", "p95 [s]"))
    fig, axes = plt.subplots(
        len(rows), len(models), figsize=(2.3 * len(models), 1.2 + 0.5 * len(deciders) * 2)
    )
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    y = np.arange(len(deciders))[::-1]
    for r, (key, label) in enumerate(rows):
        for c, model in enumerate(models):
            ax = axes[r][c]
            values = [reports[d, model][key] for d in deciders]
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
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
