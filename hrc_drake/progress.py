"""A progress line for long work: redrawn in place on a terminal, a line now and then otherwise."""

from __future__ import annotations

import sys
import time


class ProgressLine:
    """Reports `update(done, total, value)` calls on stderr, at most every `interval` seconds."""

    def __init__(self, label: str, unit: str = "step", interval: float = 0.5, stream=None):
        self.label, self.unit, self.interval = label, unit, interval
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last = 0.0
        self._start = time.perf_counter()
        self._shown = False

    def update(self, done: int, total: int = 0, value: float | None = None) -> None:
        """Record progress: `done` of `total` (0: unknown), with the latest value."""
        now = time.perf_counter()
        if now - self._last < self.interval:
            return
        self._last = now
        of = f"/{total}" if total else ""
        extra = f", last {value:.3g}" if value is not None else ""
        text = f"{self.label}: {self.unit} {done}{of}{extra} ({now - self._start:.1f} s)"
        if self.tty:
            self.stream.write("\r" + text.ljust(70))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self._shown = True

    def __enter__(self) -> ProgressLine:
        return self

    def __exit__(self, *exc) -> None:
        if self._shown and self.tty:
            self.stream.write("\n")
            self.stream.flush()
