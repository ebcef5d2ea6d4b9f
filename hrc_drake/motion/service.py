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
time); the plans come back as plain data (`plan_io`) over a pipe the caller reads without ever
blocking, and are rebuilt in the caller a few pieces per `poll`, within a time budget.
`InlinePlanService` plans inside `request` with any planner function (tests use it with planners
that misplace a part). Requests are planned in the order they were made; the planner reseeds its
random IK seeds for each plan, so the same request gives the same plan in any process, in any
order (same seed, same result).
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import multiprocessing
import os
import pickle
import select
import signal
import struct
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.plan_io import plan_from_data_in_steps, plan_to_data
from hrc_drake.motion.poses import (
    pose_from_values,
    pose_values,
    quantize_joints,
    quantize_opening,
    quantize_pose,
)
from hrc_drake.tasks.tokens import UNDO

PlanFunction = Callable[..., Plan]
"""(configuration, task, last_token, layout) -> Plan: the Supervisor's planner signature. A
request with a measured pick, start or obstacle, or a held part, calls it with the keywords of
`PlanRequest.keywords` too (`instance`, `source_pose` as a RigidTransform, `q_start` as an array,
`obstacle` as a RigidTransform, `held`, `start_opening`), as `MotionPlanner.plan_task` takes
them; an ordinary request never does."""


@dataclass(frozen=True)
class PlanRequest:
    """What a task plan depends on: build it with `PlanRequest.of`.

    Attributes:
        configuration: the tokens in place before the task.
        task: the task token (`F1`, `undo`, ...).
        last_token: the task done last (`undo` takes its part back).
        layout: (instance, token) for each placed part, sorted, as the cell measured it; None:
            the robot's own routine (`default_layout`).
        instance: the part instance the task moves (None: the lowest-numbered free one);
            required with `source_pose`.
        source_pose: where that part lies, measured, not seated (it is not in `layout`):
            (x, y, z, qw, qx, qy, qz) in the world, translation then
            `RotationMatrix.ToQuaternion()`; None: its tray home.
        start: the 6 UR3 joint positions the plan starts from; None: the planner's `q_home`.
        obstacle: the world pose (7 values, as `source_pose`) of a temporary obstacle the cell
            measures (`hrc_drake.obstacle_models`); None: no obstacle.
        held: `instance` is in the gripper already, the arm at `start` (a re-target, or with
            `undo` a swap: the part goes back to its tray home).
        start_opening: the gripper's opening at `start` [m] (None: the pick's own opening). A
            plan that starts with the fingers by a part keeps it until the arm is clear of the
            cell: closing them there at once would close them on that part.
    """

    configuration: frozenset[str]
    task: str
    last_token: str | None = None
    layout: tuple[tuple[str, str], ...] | None = None
    instance: str | None = None
    source_pose: tuple[float, ...] | None = None
    start: tuple[float, ...] | None = None
    obstacle: tuple[float, ...] | None = None
    held: bool = False
    start_opening: float | None = None

    @staticmethod
    def of(
        configuration: Iterable[str],
        task: str,
        last_token: str | None = None,
        layout: Mapping[str, str] | None = None,
        *,
        instance: str | None = None,
        source_pose: Sequence[float] | RigidTransform | None = None,
        start: Sequence[float] | None = None,
        obstacle: Sequence[float] | RigidTransform | None = None,
        held: bool = False,
        start_opening: float | None = None,
    ) -> PlanRequest:
        """From the planner's arguments (`layout`: instance -> token, e.g. measured;
        `source_pose` and `obstacle`: 7 values or a RigidTransform, the latter empty for none;
        `start`: 6 joint positions; `held`: the instance is in the gripper at `start`;
        `start_opening`: the gripper's opening there, with `start` only).
        ValueError for a source pose without its instance, a held part without its instance
        and start, or values of the wrong count."""
        placed = None if layout is None else tuple(sorted(layout.items()))
        if source_pose is not None:
            if instance is None:
                raise ValueError(
                    f"task {task}: a source pose needs the part lying there (instance=)"
                )
            if isinstance(source_pose, RigidTransform):
                source_pose = pose_values(source_pose)
            source_pose = tuple(float(v) for v in source_pose)
            quantize_pose(source_pose)  # checks the values
        if start is not None:
            start = tuple(float(v) for v in np.asarray(start, dtype=float).ravel())
            quantize_joints(start)
        if held and (instance is None or start is None):
            raise ValueError(f"task {task}: a held part needs its instance and start")
        if start_opening is not None:
            # Home's opening is the plan's own; a held part's grip sets it.
            held_or_home = start is None or held
            start_opening = None if held_or_home else quantize_opening(start_opening)
        if isinstance(obstacle, RigidTransform):
            obstacle = pose_values(obstacle)
        if obstacle is not None and len(obstacle) == 0:
            obstacle = None
        if obstacle is not None:
            obstacle = tuple(float(v) for v in obstacle)
            quantize_pose(obstacle)  # checks the values
        return PlanRequest(
            frozenset(configuration),
            task,
            last_token,
            placed,
            instance,
            source_pose,
            start,
            obstacle,
            bool(held),
            start_opening,
        )

    def layout_map(self) -> dict[str, str] | None:
        """The layout as instance -> token (the planner's argument)."""
        return None if self.layout is None else dict(self.layout)

    def keywords(self) -> dict:
        """The planner's keyword arguments for a measured pick, start or obstacle (`instance`,
        `source_pose` and `obstacle` as RigidTransforms, `q_start` as an array); {} for an
        ordinary request."""
        if self._ordinary():
            return {}
        keywords = {
            "instance": self.instance,
            "source_pose": None if self.source_pose is None else pose_from_values(self.source_pose),
            "q_start": None if self.start is None else np.array(self.start),
        }
        if self.obstacle is not None:
            keywords["obstacle"] = pose_from_values(self.obstacle)
        if self.held:
            keywords["held"] = True
        if self.start_opening is not None:
            keywords["start_opening"] = self.start_opening
        return keywords

    def _ordinary(self) -> bool:
        return (
            self.instance is None
            and self.source_pose is None
            and self.start is None
            and self.obstacle is None
            and not self.held
        )

    def key(self) -> tuple:
        """Requests with equal keys get the same plan: with a measured layout, the last task
        matters only to `undo` (as in `MotionPlanner`'s own cache key); a measured pose and
        start count to 0.1 mm and 1e-4 (`poses.KEY_DIGITS`), as the planner rounds them."""
        last = self.last_token if self.layout is None or self.task == UNDO else None
        key = (self.configuration, self.task, last, self.layout)
        if self._ordinary():
            return key
        source = None if self.source_pose is None else quantize_pose(self.source_pose)
        start = None if self.start is None else quantize_joints(self.start)
        obstacle = None if self.obstacle is None else quantize_pose(self.obstacle)
        return (*key, self.instance, source, start, obstacle, self.held, self.start_opening)


@dataclass(frozen=True)
class PlanFailure:
    """No plan for a request: `kind` is the error's class (UnreachableError, PlanningError,
    ValueError, ...), `reason` its message (it names the task, the pose and the constraint)."""

    request: PlanRequest
    kind: str
    reason: str

    @property
    def task(self) -> str:
        """The task that has no plan."""
        return self.request.task

    def __str__(self) -> str:
        request = self.request
        if request.held and request.task == UNDO:
            # A swap's return: the part in the gripper goes back to its tray, not an undo of
            # the last task (which, from an empty base, there is none).
            what = f"putting {request.instance} back in its tray"
        else:
            what = request.task
        return f"no plan for {what} from {sorted(request.configuration)}: {self.reason}"


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


# Worker process: messages in (parent -> worker, `Connection.send` over a pipe):
#   ("plan", id, PlanRequest) | ("reach",) | ("stop",)
# and out (worker -> parent, length-prefixed pickles over a second pipe, `_FrameWriter` and
# `_FrameReader`):
#   ("ready", q_home, monotonic time) | ("error", kind, message) at start;
#   ("started", id); ("plan", id, data, seconds) | ("failure", id, kind, message, seconds) |
#   ("crash", id, traceback); ("reach", message | None).
#
# Why not a multiprocessing.Queue out: its feeder thread in the worker writes a message's length
# and its body in two writes, and between them waits for the interpreter lock, which the
# planner holds for the length of a solver call (hundreds of ms). A parent reading that message
# blocks until then (measured: single polls of 270–380 ms). Here the worker writes each frame
# from its one thread in one go, and the parent reads whatever bytes are there, never blocking.

_HEADER = struct.Struct("<Q")
# The results pipe's capacity (Linux F_SETPIPE_SZ; the default is 64 KiB, a plan is about
# 30 KB): the worker blocks only when this much is unread.
_PIPE_BYTES = 1 << 20


class _FrameWriter:
    """The worker's end of the results pipe: one write of length + pickle per message."""

    def __init__(self, connection):
        self._connection = connection  # keeps the descriptor open
        self._fd = connection.fileno()
        with contextlib.suppress(AttributeError, OSError):  # not Linux, or a lower limit
            fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)

    def put(self, message: tuple) -> None:
        payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(_HEADER.pack(len(payload)) + payload)
        while view:
            view = view[os.write(self._fd, view) :]


class _FrameReader:
    """The parent's end of the results pipe, read without blocking."""

    def __init__(self, connection):
        self._connection = connection
        self.fd = connection.fileno()
        os.set_blocking(self.fd, False)
        self._buffer = bytearray()
        self.eof = False

    def messages(self) -> list[tuple]:
        """Every whole message that has arrived (a partial one stays for the next call)."""
        while not self.eof:
            try:
                chunk = os.read(self.fd, _PIPE_BYTES)
            except BlockingIOError:
                break
            if not chunk:
                self.eof = True  # the worker has exited
            self._buffer += chunk
        out = []
        while len(self._buffer) >= _HEADER.size:
            (size,) = _HEADER.unpack_from(self._buffer)
            end = _HEADER.size + size
            if len(self._buffer) < end:
                break
            out.append(pickle.loads(self._buffer[_HEADER.size : end]))
            del self._buffer[:end]
        return out

    def close(self) -> None:
        self._connection.close()


@contextlib.contextmanager
def _main_script_hidden():
    """While a worker is spawned, hide the caller's main script from multiprocessing: a spawned
    child otherwise runs it again (as `__mp_main__`), and a script without an
    `if __name__ == "__main__":` guard would start its whole run in the worker. The worker
    needs nothing from it (its target lives in this module)."""
    main = sys.modules.get("__main__")
    if main is None:
        yield
        return
    saved = {
        name: main.__dict__[name] for name in ("__file__", "__spec__") if name in main.__dict__
    }
    main.__dict__.pop("__file__", None)
    main.__spec__ = None
    try:
        yield
    finally:
        main.__dict__.pop("__spec__", None)
        main.__dict__.update(saved)


def _serve(requests, results, options: MotionOptions, design: CellDesign, nice: int) -> None:
    """The worker's loop: one MotionPlanner (and its plan cache), requests in order."""
    # Ctrl-C goes to the whole process group; the parent decides when the worker ends.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if nice:
        os.nice(nice)
    results = _FrameWriter(results)
    from hrc_drake.motion.planner import MotionPlanner

    try:
        planner = MotionPlanner(options, design=design)
    except (CellModelError, RuntimeError, ValueError) as err:
        results.put(("error", type(err).__name__, str(err)))
        return
    results.put(("ready", planner.q_home.tolist(), time.monotonic()))
    # EOFError on reading or BrokenPipeError on writing: the parent is gone, and so the worker.
    with contextlib.suppress(EOFError, BrokenPipeError):
        while (message := requests.recv())[0] != "stop":
            if message[0] == "plan":
                results.put(("started", message[1]))  # the parent times each plan from here
            results.put(_answer(planner, message))


def _answer(planner, message: tuple) -> tuple:
    """The worker's answer to a "reach" or "plan" message."""
    from hrc_drake.motion.planner import check_reach

    if message[0] == "reach":
        try:
            check_reach(planner)
        except CellModelError as err:
            return ("reach", str(err))
        return ("reach", None)
    _, ident, request = message
    start = time.perf_counter()
    try:
        plan = planner.plan_task(
            request.configuration,
            request.task,
            last_token=request.last_token,
            layout=request.layout_map(),
            **request.keywords(),
        )
        seconds = time.perf_counter() - start  # planning only, not the encoding
        return ("plan", ident, plan_to_data(plan), seconds)
    except (RuntimeError, ValueError) as err:  # UnreachableError, PlanningError, bad input
        return ("failure", ident, type(err).__name__, str(err), time.perf_counter() - start)
    except Exception:
        return ("crash", ident, traceback.format_exc())


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
            target=_serve,
            args=(receiver, results_out, self.options, design, nice),
            name="hrc-drake planner",
            daemon=True,
        )
        self._started_at = time.monotonic()
        with _main_script_hidden():
            self._process.start()
        # The worker's ends: a dead worker then breaks the request pipe and ends the results.
        receiver.close()
        results_out.close()
        self._results = _FrameReader(results_in)
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
    options: MotionOptions, design: CellDesign | None = None
) -> WorkerPlanService:
    """One worker (and its plan cache) per cell and set of options, shared by a process's runs,
    like `shared_planner`; a closed or dead one is replaced. All end at exit."""
    if design is None:
        from hrc_drake.tasks.spec import load_spec

        design = CellDesign.of(load_spec())
    key = (options, design.key())
    service = _SHARED.get(key)
    if service is None or not service.alive:
        service = _SHARED[key] = WorkerPlanService(options, design)
    return service


@atexit.register
def _close_all() -> None:
    for service in list(_LIVE):
        service.close()


__all__ = [
    "InlinePlanService",
    "PlanFailure",
    "PlanFunction",
    "PlanRequest",
    "PlanService",
    "PlanServiceError",
    "WorkerPlanService",
    "planner_function",
    "shared_plan_service",
]
