"""The plan service's worker process: its loop (`serve`), one `MotionPlanner` answering requests
in order, and the results pipe it answers on (`FrameWriter` in the worker, `FrameReader` in the
caller).

Apart from the service because this is the other process's side of it (and the bytes between
the two): `WorkerPlanService` starts `serve` in a spawned process and reads what it writes.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import pickle
import signal
import struct
import sys
import time
import traceback

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan_io import plan_to_data

# Worker process: messages in (parent -> worker, `Connection.send` over a pipe):
#   ("plan", id, PlanRequest) | ("reach",) | ("stop",)
# and out (worker -> parent, length-prefixed pickles over a second pipe, `FrameWriter` and
# `FrameReader`):
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


class FrameWriter:
    """The worker's end of the results pipe: one write of length + pickle per message."""

    def __init__(self, connection):
        self._connection = connection  # keeps the descriptor open
        self._fd = connection.fileno()
        with contextlib.suppress(AttributeError, OSError):  # not Linux, or a lower limit
            fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, _PIPE_BYTES)

    def put(self, message: tuple) -> None:
        """Send `message` as one frame (blocking only while the pipe is full)."""
        payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(_HEADER.pack(len(payload)) + payload)
        while view:
            view = view[os.write(self._fd, view) :]


class FrameReader:
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
        """Close the parent's end."""
        self._connection.close()


@contextlib.contextmanager
def main_script_hidden():
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


def serve(requests, results, options: MotionOptions, design: CellDesign, nice: int) -> None:
    """The worker's loop: one MotionPlanner (and its plan cache), requests in order."""
    # Ctrl-C goes to the whole process group; the parent decides when the worker ends.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if nice:
        os.nice(nice)
    results = FrameWriter(results)
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
    from hrc_drake.motion.reach_check import check_reach

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
