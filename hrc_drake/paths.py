"""Output paths checked before any work is done.

A command that writes a file (`--out`, `--record`, `--still`, `--plot`) calls `check_output_path`
first, so that a directory, a device, a missing folder or a place where no file can be made is a
one-line error at once, not a traceback (or a replaced device node) after minutes of training or
simulation.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path


class UsageError(ValueError):
    """A command-line value that cannot be used; the message names the flag and the fix."""


def check_output_path(path: str | Path, flag: str, suffixes: Iterable[str] | None = None) -> Path:
    """`path` as a Path if a file can be written there; UsageError naming `flag` otherwise.

    Refused: an existing directory (or a name ending in a separator), anything else that exists
    and is not a regular file (a device such as /dev/null, a pipe, a socket: files are written by
    replacing them, which would replace the device), a file name whose suffix is not one of
    `suffixes` (compared case-insensitively, e.g. ``(".png", ".pdf")``), a parent folder that
    does not exist or is not a folder, and a folder where this process cannot create a file.
    The last is tried, not inferred: a probe file is created next to `path` and removed at once
    (`os.access` says yes to root everywhere, also under /proc and /sys). Nothing else is written.
    """
    text = str(path)
    path = Path(path)
    if not text or text.endswith((os.sep, "/")) or path.is_dir():
        raise UsageError(
            f"{flag} {text}: is a directory; give a file name inside it "
            f"({flag} {path / ('NAME' + _first(suffixes))})"
        )
    _refuse_special_file(path, text, flag)
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
    _probe(parent, text, flag)
    return path


def _refuse_special_file(path: Path, text: str, flag: str) -> None:
    try:
        mode = path.stat().st_mode  # follows a symbolic link: what a write would reach
    except (FileNotFoundError, NotADirectoryError):
        return  # nothing there yet; a missing folder is reported below
    except OSError as err:
        raise UsageError(
            f"{flag} {text}: cannot be used ({err.strerror}); choose another name"
        ) from None
    if not stat.S_ISREG(mode):
        raise UsageError(
            f"{flag} {text}: exists and is not a regular file ({_kind(mode)}); writing would "
            "replace it: give the name of a new or regular file"
        )


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a named pipe"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "a special file"


def _probe(parent: Path, text: str, flag: str) -> None:
    """Create and remove a file in `parent`, as the atomic write will (hrc_drake.atomic)."""
    try:
        fd, probe = tempfile.mkstemp(dir=parent, prefix=".hrc-drake-probe.", suffix=".tmp")
    except OSError as err:
        raise UsageError(
            f"{flag} {text}: no file can be created in {parent} ({err.strerror}); "
            "choose another place"
        ) from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError as err:
        raise UsageError(
            f"{flag} {text}: a file created in {parent} cannot be removed again "
            f"({err.strerror}); choose another place"
        ) from None


def _first(suffixes: Iterable[str] | None) -> str:
    for suffix in suffixes or ():
        return suffix.lower()
    return ""
