"""`hrc-drake simulate` as a separate process, as a person starts it in a terminal: its output is
read as it comes (the browser and interrupt tests wait for its prompts), and it can be sent
Ctrl-C (SIGINT)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path


def hrc_drake_command() -> list[str]:
    """The `hrc-drake` console script beside this interpreter (the environment the tests run
    in), else the same `hrc_drake.cli` run as a module."""
    script = Path(sys.executable).with_name("hrc-drake")
    return [str(script)] if script.exists() else [sys.executable, "-m", "hrc_drake.cli"]


class SimulateProcess:
    """`hrc-drake simulate ARGS` (or another `command`); its stderr lines are collected as they
    come."""

    def __init__(self, *args: str, command: str = "simulate"):
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.args = (command, *args)
        self.proc = subprocess.Popen(
            [*hrc_drake_command(), command, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        self._lines: list[str] = []
        self._out: list[str] = []
        self._changed = threading.Condition()
        self._readers = [
            threading.Thread(target=self._read, args=(self.proc.stderr, self._lines), daemon=True),
            threading.Thread(target=self._read, args=(self.proc.stdout, self._out), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def _read(self, stream, into: list[str]) -> None:
        for line in stream:
            with self._changed:
                into.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def stderr_lines(self) -> list[str]:
        """The stderr lines so far."""
        with self._changed:
            return list(self._lines)

    def wait_for_line(self, pattern: str, timeout: float, start: int = 0) -> re.Match:
        """The first stderr line from index `start` on that matches `pattern` (re.search);
        AssertionError with the output's tail if the process ends or `timeout` passes first."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                for line in self._lines[start:]:
                    match = regex.search(line)
                    if match:
                        return match
                start = max(start, len(self._lines))
                left = deadline - time.monotonic()
                if self.proc.poll() is not None and not any(r.is_alive() for r in self._readers):
                    raise AssertionError(self._story(f"ended before printing /{pattern}/"))
                if left <= 0:
                    raise AssertionError(self._story(f"printed no /{pattern}/ in {timeout} s"))
                self._changed.wait(min(left, 0.5))

    def interrupt(self) -> None:
        """Ctrl-C: SIGINT, as the terminal sends it."""
        self.proc.send_signal(signal.SIGINT)

    def finish(self, timeout: float) -> tuple[int, str, list[str]]:
        """Wait for the end; returns (exit status, stdout, stderr lines)."""
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired as err:
            raise AssertionError(self._story(f"still running after {timeout} s")) from err
        for reader in self._readers:
            reader.join(10)
        return code, "\n".join(self._out), self.stderr_lines

    def kill(self) -> None:
        """Stop the process if it still runs (a failed test must not leave it serving)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def _story(self, what: str) -> str:
        tail = "\n".join(self.stderr_lines[-15:])
        return f"hrc-drake {' '.join(self.args)}: {what}; stderr ends:\n{tail}"


__all__ = ["SimulateProcess", "hrc_drake_command"]
