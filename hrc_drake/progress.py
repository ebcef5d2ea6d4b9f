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
        """Record progress: `done` of `total` (0: unknown), with the latest value. The last
        update (`done` == `total`) is always shown; with a total, the time left is estimated
        from the pace so far."""
        now = time.perf_counter()
        last = bool(total) and done >= total
        if now - self._last < self.interval and not last:
            return
        self._last = now
        of = f"/{total}" if total else ""
        extra = f", last {value:.3g}" if value is not None else ""
        elapsed = now - self._start
        left = ""
        if total and 0 < done < total and elapsed >= 1.0:  # a pace worth extrapolating
            left = f", about {duration(elapsed / done * (total - done))} left"
        text = f"{self.label}: {self.unit} {done}{of}{extra} ({elapsed:.1f} s{left})"
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


def duration(seconds: float) -> str:
    """`seconds` as a person reads it: 42 s, 7 min, 3.5 h, 2.1 days."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    if seconds < 36 * 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"
