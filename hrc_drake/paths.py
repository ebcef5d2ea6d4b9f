"""Output paths checked before any work is done.

A command that writes a file (`--out`, `--record`, `--still`, `--plot`) calls `check_output_path`
first, so that a directory, a device, a missing folder or a place where no file can be made is a
one-line error at once, not a traceback (or a replaced device node) after minutes of training or
simulation. One rule for files that exist: a command replaces only a file of the kind it writes
(a policy with a policy, a PNG with a PNG; each writer passes its `OutputKind`), anything else
only with `--force` (`hrc-drake solve --out notes.md` must not destroy the notes).
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path


class UsageError(ValueError):
    """A command-line value that cannot be used; the message names the flag and the fix."""


@dataclass(frozen=True)
class OutputKind:
    """The kind of file a command writes, for `check_output_path`: `name` in messages ("policy
    file") and `recognise(path)`, True when an existing file is one (so replacing it with a new
    one is what the user asked for); `example`, a file name a hint may advise ("policy.json";
    empty: the given name's stem and suffix)."""

    name: str
    recognise: Callable[[Path], bool]
    example: str = ""


def _head(path: Path) -> bytes:
    """The first bytes of `path` (empty if it cannot be read)."""
    try:
        with open(path, "rb") as f:
            return f.read(512)
    except OSError:
        return b""


def _starts_with(*magics: bytes) -> Callable[[Path], bool]:
    def recognise(path: Path) -> bool:
        head = _head(path).lstrip().lower()
        return any(head.startswith(m.lower()) for m in magics)

    return recognise


# Files recognised by their first bytes: what a reader of the format checks first too.
PNG_FILE = OutputKind("PNG image", _starts_with(b"\x89PNG"))
PDF_FILE = OutputKind("PDF file", _starts_with(b"%PDF"))
SVG_FILE = OutputKind("SVG image", _starts_with(b"<?xml", b"<svg"))
# Drake's Meshcat page names itself in its <title>, within the first bytes.
MESHCAT_RECORDING = OutputKind(
    "Meshcat recording",
    lambda path: _starts_with(b"<!doctype html")(path) and b"meshcat" in _head(path).lower(),
)


def image_kind(suffix: str) -> OutputKind:
    """The OutputKind of a plot file with this suffix (.png, .pdf, .svg)."""
    return {".pdf": PDF_FILE, ".svg": SVG_FILE}.get(suffix.lower(), PNG_FILE)


def check_output_path(
    path: str | Path,
    flag: str,
    suffixes: Iterable[str] | None = None,
    kind: OutputKind | None = None,
    force: bool = False,
) -> Path:
    """`path` as a Path if a file can be written there; UsageError naming `flag` otherwise.

    An existing regular file is replaced only if `kind` recognises it as a file of the kind the
    command writes, or with `force` (`--force`); a writer that passes no `kind` replaces any
    regular file (kept for callers outside the command line).

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
    if kind is not None and not force and path.is_file() and not kind.recognise(path):
        raise UsageError(
            f"{flag} {text}: exists and is not a {kind.name}; writing would destroy it: choose a "
            f"new name (e.g. {flag} {_example(path, kind)}), or add --force to replace it"
        )
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


def _example(path: Path, kind: OutputKind) -> Path:
    if not kind.example:
        return fresh_name(path)
    example = Path(kind.example)
    return fresh_name(path, example.stem, example.suffix)


def fresh_name(path: str | Path, stem: str | None = None, suffix: str | None = None) -> Path:
    """A name beside `path` that does not exist yet (`stem` and `suffix`, default `path`'s, then
    `-2`, `-3`, ...): what a hint advises instead of overwriting a file it does not know."""
    path = Path(path)
    stem = stem or path.stem
    suffix = suffix or path.suffix
    for n in range(1, 1000):
        candidate = path.with_name(f"{stem}{'' if n == 1 else f'-{n}'}{suffix}")
        if not candidate.exists():
            return candidate
    return path.with_name(f"{stem}-new{suffix}")


def not_a_file(path: str | Path) -> str:
    """What `path`, which exists and is not a regular file, is, for a one-line error: ``is a
    character device, not a regular file``."""
    try:
        mode = Path(path).stat().st_mode
    except OSError as err:
        return f"cannot be used ({err.strerror})"
    kind = "a folder" if stat.S_ISDIR(mode) else _kind(mode)
    return f"is {kind}, not a regular file"


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
