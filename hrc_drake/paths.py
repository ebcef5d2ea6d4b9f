"""Output paths checked before any work is done.

A command that writes a file (`--out`, `--record`, `--still`) calls `check_output_path` first,
so that a directory, a missing folder or a read-only place is a one-line error at once, not a
traceback after minutes of training or simulation.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path


class UsageError(ValueError):
    """A command-line value that cannot be used; the message names the flag and the fix."""


def check_output_path(path: str | Path, flag: str, suffixes: Iterable[str] | None = None) -> Path:
    """`path` as a Path if a file can be written there; UsageError naming `flag` otherwise.

    Refused: an existing directory (or a name ending in a separator), a file name whose suffix
    is not one of `suffixes` (compared case-insensitively, e.g. ``(".png", ".pdf")``), a parent
    folder that does not exist or is not a folder, and a folder this process cannot write to.
    Nothing is created or written.
    """
    text = str(path)
    path = Path(path)
    if not text or text.endswith((os.sep, "/")) or path.is_dir():
        raise UsageError(
            f"{flag} {text}: is a directory; give a file name inside it "
            f"({flag} {path / ('NAME' + _first(suffixes))})"
        )
    if suffixes is not None:
        allowed = [s.lower() for s in suffixes]
        if path.suffix.lower() not in allowed:
            got = f"{path.suffix!r}" if path.suffix else "no extension"
            raise UsageError(
                f"{flag} {text}: {got} is not supported; use one of {', '.join(allowed)}"
            )
    parent = path.parent
    if not parent.exists():
        raise UsageError(
            f"{flag} {text}: folder {parent} does not exist; create it (mkdir -p {parent}) "
            "or choose another place"
        )
    if not parent.is_dir():
        raise UsageError(f"{flag} {text}: {parent} is not a folder; choose another place")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"{flag} {text}: folder {parent} is not writable; choose another place")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{flag} {text}: the file is read-only; choose another name")
    return path


def _first(suffixes: Iterable[str] | None) -> str:
    for suffix in suffixes or ():
        return suffix.lower()
    return ""
