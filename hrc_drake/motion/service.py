"""Planning beside the control loop: a small non-blocking plan service.

A controller (the Supervisor) must never wait for the planner inside its update: a task plan
takes 0.2–1 s, a servo update a few milliseconds. So the controller asks (`request`), goes on
holding a safe state, and asks again at each update (`poll`) until the plan is there:

    service.request(PlanRequest.of(tokens, task, last, layout))   # returns at once
    ...
    result = service.poll(request)     # None (not ready), a Plan, or a PlanFailure

A request may also pick its part where it was measured lying (`instance`, `source_pose`) and
start from the arm's measured posture (`start`): the re-grasp after a drop, the re-place of a
part that did not seat.

`WorkerPlanService` plans in a persistent worker process with its own `MotionPlanner` (a Python
thread would take the interpreter lock from the control loop for tens of milliseconds at a
time; the worker's side is `plan_worker`); the plans come back as plain data (`plan_io`) over a
pipe the caller reads without ever blocking, and are rebuilt in the caller a few pieces per
`poll`, within a time budget.
`InlinePlanService` plans inside `request` with any planner function (tests use it with planners
that misplace a part). Requests are planned in the order they were made; the planner reseeds its
random IK seeds for each plan, so the same request gives the same plan in any process, in any
order (same seed, same result). The requests and results themselves are `plan_request`'s.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing
import select
import time
from collections.abc import Callable, Iterator
from typing import Protocol

import numpy as np

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.plan_io import plan_from_data_in_steps
from hrc_drake.motion.plan_request import PlanFailure, PlanFunction, PlanRequest
from hrc_drake.motion.plan_worker import FrameReader, main_script_hidden, serve


class PlanServiceError(RuntimeError):
    """The plan service itself failed: its worker died, hung past its time-out, or the service
    was closed. Not a planning failure (those are `PlanFailure` values)."""


class PlanService(Protocol):
    """What a controller calls from its update; none of these waits for a plan."""

    def request(self, request: PlanRequest) -> None:
        """Ask for a plan (again asking for one asked before does nothing)."""

    def poll(self, request: PlanRequest) -> Plan | PlanFailure | None:
        """The result of a request made before; None while it is not ready."""

    def is_cached(self, request: PlanRequest) -> bool:
        """Whether the request was planned before (the `plan_ready` of run reports)."""

    def pending(self) -> int:
        """How many requests are asked and not answered yet."""

    def close(self) -> None:
        """Release the service (end its worker)."""


class InlinePlanService:
    """Plans synchronously inside `request` with a planner function; results are ready at once.

    For tests and tools: e.g. `InlinePlanService(misplacing_planner)`. Planning errors
    (RuntimeError: UnreachableError, PlanningError; ValueError) become `PlanFailure` values.
    """

    def __init__(self, plan_fn: PlanFunction):
        self._plan_fn = plan_fn
        self._results: dict[tuple, Plan | PlanFailure] = {}

    def request(self, request: PlanRequest) -> None:
        """Plan now, unless this request was planned before."""
        key = request.key()
        if key in self._results:
            return
        try:
            plan = self._plan_fn(
                request.configuration,
                request.task,
                request.last_token,
                request.layout_map(),
                **request.keywords(),
            )
        except (RuntimeError, ValueError) as err:
            self._results[key] = PlanFailure(request, type(err).__name__, str(err))
        else:
            self._results[key] = plan

    def poll(self, request: PlanRequest) -> Plan | PlanFailure | None:
        """The result of `request` (made before: ValueError otherwise)."""
        try:
            return self._results[request.key()]
        except KeyError:
            raise ValueError(f"poll of a plan never requested: {request}") from None

    def is_cached(self, request: PlanRequest) -> bool:
        """Whether `request` was planned before."""
        return request.key() in self._results

    def pending(self) -> int:
        """None: every request is answered at once."""
        return 0

    def wait(self, request: PlanRequest, timeout: float | None = None) -> Plan | PlanFailure:
        """Request and return the result (planned at once)."""
        self.request(request)
        return self.poll(request)

    def wait_all(self, timeout: float | None = None) -> None:
        """Nothing to wait for."""

    def close(self) -> None:
        """Nothing to release."""


def planner_function(planner) -> PlanFunction:
    """A `MotionPlanner`'s `plan_task` as a plan function (for `InlinePlanService`)."""

    def plan(configuration, task, last_token, layout, **measured):
        return planner.plan_task(
            configuration, task, last_token=last_token, layout=layout, **measured
        )

    return plan


class _Rebuild:
    """A plan arriving as plain data, rebuilt a few pieces per poll."""

    def __init__(self, data: dict):
        self._steps: Iterator[Plan | None] = plan_from_data_in_steps(data)

    def advance(self, budget: float | None) -> Plan | None:
        """Rebuild until done or `budget` seconds are spent (None: no limit)."""
        deadline = None if budget is None else time.perf_counter() + budget
        for result in self._steps:
            if result is not None:
                return result
            if deadline is not None and time.perf_counter() >= deadline:
                return None
        raise AssertionError("plan_from_data_in_steps ends with the plan")


class WorkerPlanService:
    """Plans in a persistent worker process holding its own `MotionPlanner` and plan cache.

    The process starts at construction (spawned: pydrake is not fork-safe once threads run);
    `request` and `poll` never wait for it. `q_home` and `check_reach` wait for the worker
    (up to `start_timeout`), for use before a run starts. A worker that dies, or works on one
    plan longer than `plan_timeout` seconds, is a `PlanServiceError` at the next call.
    `rebuild_budget`: seconds of a `poll` spent rebuilding an arrived plan (the rest at the next
    polls). `nice`: added to the worker's niceness, so that on a busy machine the kernel runs
    the control loop before the planner.
    """

    def __init__(
        self,
        options: MotionOptions | None = None,
        design: CellDesign | None = None,
        *,
        start_timeout: float = 120.0,
        plan_timeout: float = 300.0,
        rebuild_budget: float | None = 0.0005,
        nice: int = 0,
    ):
        if multiprocessing.current_process().daemon:
            raise PlanServiceError(
                "a daemonic process (a multiprocessing Pool's worker) cannot start a planning "
                "worker; plan in that process: InlinePlanService(planner_function(planner))"
            )
        self.options = options or MotionOptions()
        if design is None:
            from hrc_drake.tasks.spec import load_spec

            design = CellDesign.of(load_spec())
        self.design = design
        self.start_timeout, self.plan_timeout = start_timeout, plan_timeout
        self.rebuild_budget = rebuild_budget
        context = multiprocessing.get_context("spawn")
        receiver, self._sender = context.Pipe(duplex=False)
        results_in, results_out = context.Pipe(duplex=False)
        self._process = context.Process(
            target=serve,
            args=(receiver, results_out, self.options, design, nice),
            name="hrc-drake planner",
            daemon=True,
        )
        self._started_at = time.monotonic()
        with main_script_hidden():
            self._process.start()
        # The worker's ends: a dead worker then breaks the request pipe and ends the results.
        receiver.close()
        results_out.close()
        self._results = FrameReader(results_in)
        self._closed = False
        self._q_home: np.ndarray | None = None
        self._start_error: tuple[str, str] | None = None
        self.start_seconds: float | None = None
        """Wall seconds from construction to the worker's planner being ready."""
        self._reach: list[str | None] = []
        self._next_id = 0
        self._keys: dict[int, tuple] = {}  # id -> key, requested and not yet answered
        self._requested: dict[tuple, PlanRequest] = {}
        self._results_by_key: dict[tuple, Plan | PlanFailure | _Rebuild] = {}
        self._running: tuple[int, float] | None = None  # (id, wall time the worker started it)
        self._worker_seconds: dict[tuple, float] = {}
        _LIVE.append(self)

    # The non-blocking calls.

    def request(self, request: PlanRequest) -> None:
        """Queue a plan for the worker; a request made before is not sent again."""
        key = request.key()
        if key in self._requested:
            return
        self._check_usable()
        ident = self._next_id
        self._next_id += 1
        try:
            # A request is a few hundred bytes; the pipe holds 64 KiB, so this never blocks.
            self._sender.send(("plan", ident, request))
        except (BrokenPipeError, ConnectionResetError, OSError) as err:
            raise self._died(f"while sending {request.task}") from err
        self._keys[ident] = key
        self._requested[key] = request

    def poll(self, request: PlanRequest) -> Plan | PlanFailure | None:
        """The result of `request` (made before: ValueError otherwise), None while not ready.

        An arrived plan is rebuilt within `rebuild_budget` per call."""
        key = request.key()
        if key not in self._requested:
            raise ValueError(f"poll of a plan never requested: {request}")
        self._drain()
        result = self._results_by_key.get(key)
        if result is None:
            self._check_progress()
            return None
        if isinstance(result, _Rebuild):
            plan = result.advance(self.rebuild_budget)
            if plan is None:
                return None
            self._results_by_key[key] = result = plan
        return result

    def is_cached(self, request: PlanRequest) -> bool:
        """Whether the worker has answered this request (its plan or failure is here)."""
        self._drain()
        return request.key() in self._results_by_key

    def pending(self) -> int:
        """How many requests the worker has not answered yet."""
        self._drain()
        return sum(key not in self._results_by_key for key in self._requested)

    def wait_all(self, timeout: float | None = None) -> None:
        """Wait until the worker has answered every request (a simulation that keeps time
        still while it plans ahead; never from a control update)."""
        limit = self.plan_timeout if timeout is None else timeout
        self._wait(lambda: self.pending() == 0, limit, "to plan ahead")

    def worker_seconds(self, request: PlanRequest) -> float | None:
        """Wall seconds the worker's planner spent on the request, without queueing, encoding
        and transfer (None: not answered yet)."""
        return self._worker_seconds.get(request.key())

    # Blocking calls, for before and after a run.

    @property
    def q_home(self) -> np.ndarray:
        """The home posture the worker's planner computed (waits for the worker to start)."""
        self._wait(lambda: self._q_home is not None, self.start_timeout, "to start")
        return self._q_home.copy()

    def check_reach(self) -> None:
        """`check_reach` of the worker's planner (the UR3 reaches every grasp of the spec):
        CellModelError naming the slot or part and the layout value to change."""
        if not self._reach:
            self._check_usable()
            self._sender.send(("reach",))
            self._wait(lambda: bool(self._reach), self.start_timeout, "to check the reach")
        if self._reach[0] is not None:
            raise CellModelError(self._reach[0])

    def wait(self, request: PlanRequest, timeout: float | None = None) -> Plan | PlanFailure:
        """Request and wait for the result (scripts and tests; never from a control update)."""
        self.request(request)
        key = request.key()
        limit = self.plan_timeout if timeout is None else timeout
        self._wait(lambda: key in self._results_by_key, limit, f"to plan {request.task}")
        result = self._results_by_key[key]
        if isinstance(result, _Rebuild):
            self._results_by_key[key] = result = result.advance(None)
        return result

    def close(self) -> None:
        """End the worker (asks it to stop, then terminates it after 5 s). Idempotent."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):  # the worker is gone already
            self._sender.send(("stop",))
        self._process.join(5.0)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(5.0)
        self._sender.close()
        self._results.close()
        if self in _LIVE:
            _LIVE.remove(self)

    @property
    def alive(self) -> bool:
        """The worker process runs and the service is open."""
        return not self._closed and self._process.is_alive()

    @property
    def pid(self) -> int | None:
        """The worker's process id."""
        return self._process.pid

    # Internals.

    def _drain(self) -> None:
        """Take every message the worker has sent, without waiting."""
        if self._closed:
            return
        for message in self._results.messages():
            self._handle(message)

    def _handle(self, message: tuple) -> None:
        kind = message[0]
        if kind == "ready":
            self._q_home = np.array(message[1], dtype=float)
            # CLOCK_MONOTONIC is one clock for every process of the machine.
            self.start_seconds = message[2] - self._started_at
        elif kind == "error":
            self._start_error = (message[1], message[2])
        elif kind == "reach":
            self._reach.append(message[1])
        elif kind == "started":
            self._running = (message[1], time.perf_counter())
        elif kind == "crash":
            self.close()
            task = self._requested[self._keys[message[1]]].task
            raise PlanServiceError(f"the planning worker failed on {task}:\n{message[2]}")
        else:
            ident = message[1]
            key = self._keys.pop(ident)
            self._running = None
            if kind == "plan":
                self._results_by_key[key] = _Rebuild(message[2])
                self._worker_seconds[key] = message[3]
            else:
                request = self._requested[key]
                self._results_by_key[key] = PlanFailure(request, message[2], message[3])
                self._worker_seconds[key] = message[4]

    def _check_usable(self) -> None:
        if self._closed:
            raise PlanServiceError("the plan service is closed")
        if self._start_error is not None:
            self._raise_start_error()
        if not self._process.is_alive():
            raise self._died("")

    def _check_progress(self) -> None:
        """While a request is pending: the worker lives, started in time and has not hung on
        one plan."""
        self._check_usable()
        if self._q_home is None and time.monotonic() - self._started_at > self.start_timeout:
            self.close()
            raise PlanServiceError(
                f"the planning worker did not start within {self.start_timeout:g} s "
                "(start_timeout); it was stopped"
            )
        if self._running is None:
            return
        ident, since = self._running
        if time.perf_counter() - since > self.plan_timeout:
            task = self._requested[self._keys[ident]].task
            self.close()
            raise PlanServiceError(
                f"the planning worker worked on {task} for more than {self.plan_timeout:g} s "
                "(plan_timeout); it was stopped"
            )

    def _wait(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.perf_counter() + timeout
        while True:
            self._drain()
            if self._start_error is not None:
                self._raise_start_error()
            if done():
                return
            self._check_progress()
            if time.perf_counter() > deadline:
                self.close()
                raise PlanServiceError(
                    f"the planning worker took more than {timeout:g} s {what}; it was stopped"
                )
            if self._results.eof:  # the worker has exited: the next check says how
                time.sleep(0.01)
            else:
                select.select([self._results.fd], [], [], 0.05)

    def _raise_start_error(self):
        kind, message = self._start_error
        self.close()
        if kind == "CellModelError":
            raise CellModelError(message)
        raise PlanServiceError(f"the planning worker could not start: {kind}: {message}")

    def _died(self, when: str) -> PlanServiceError:
        self._process.join(0.1)
        code = self._process.exitcode
        pending = sorted(self._requested[k].task for k in self._keys.values())
        self.close()
        how = (
            f"was killed by signal {-code}"
            if code is not None and code < 0
            else (f"exited with status {code}")
        )
        return PlanServiceError(
            f"the planning worker (pid {self._process.pid}) {how}{' ' + when if when else ''}"
            + (f"; plans pending: {', '.join(pending)}" if pending else "")
        )


_LIVE: list[WorkerPlanService] = []
_SHARED: dict[tuple, WorkerPlanService] = {}


def shared_plan_service(
    options: MotionOptions, design: CellDesign | None = None, nice: int = 0
) -> WorkerPlanService:
    """One worker (and its plan cache) per cell, set of options and `nice` (the worker's, see
    `WorkerPlanService`), shared by a process's runs, like `shared_planner`; a closed or dead
    one is replaced. All end at exit."""
    if design is None:
        from hrc_drake.tasks.spec import load_spec

        design = CellDesign.of(load_spec())
    key = (options, design.key(), nice)
    service = _SHARED.get(key)
    if service is None or not service.alive:
        service = _SHARED[key] = WorkerPlanService(options, design, nice=nice)
    return service


@atexit.register
def _close_all() -> None:
    for service in list(_LIVE):
        service.close()


__all__ = [
    "InlinePlanService",
    "PlanService",
    "PlanServiceError",
    "WorkerPlanService",
    "planner_function",
    "shared_plan_service",
]
