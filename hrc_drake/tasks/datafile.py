"""Versioned, checksummed JSON files (policies, cost tables): one writer and one reader.

A file is a JSON object with `format`, `version` and a `checksum` of the rest; it is written
atomically. Reading refuses, with a one-line error that ends with the fix, a directory, a
missing or unreadable file, a file that is not JSON, another format, another version, and a
checksum that does not match (a file edited or cut short).
"""

from __future__ import annotations

import gc
import hashlib
import json
from collections.abc import Callable, Collection, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from hrc_drake.atomic import atomic_write_text


@contextmanager
def gc_paused() -> Iterator[None]:
    """The cyclic garbage collector off for a block that builds millions of objects that hold
    no cycles (a parsed policy file, a table of sequences): every collection in the block would
    walk all the objects made so far (8 s instead of 1.4 s to parse a policy of 10^6 states).
    Reference counting still frees what the block drops."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


_CANONICAL = json.JSONEncoder(sort_keys=True, separators=(",", ":"))


def checksum(payload: Mapping[str, Any]) -> str:
    """SHA-256 of the payload's canonical JSON (`json.dumps(payload, sort_keys=True,
    separators=(",", ":"))`), hashed piece by piece: a list under a top-level key one item at
    a time, so that a policy of 10^6 states is not held a second time as millions of chunks."""
    digest = hashlib.sha256()
    digest.update(b"{")
    for i, key in enumerate(sorted(payload)):
        digest.update(f"{',' if i else ''}{json.dumps(key)}:".encode())
        value = payload[key]
        if isinstance(value, list):
            digest.update(b"[")
            for j, item in enumerate(value):
                digest.update((b"," if j else b"") + _CANONICAL.encode(item).encode())
            digest.update(b"]")
        else:
            digest.update(_CANONICAL.encode(value).encode())
    digest.update(b"}")
    return digest.hexdigest()


def with_checksum(payload: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of `payload` with its `checksum` added."""
    out = dict(payload)
    out["checksum"] = checksum(payload)
    return out


def save_checked_json(
    path: str | Path, payload: Mapping[str, Any], rows: Collection[str] = ()
) -> None:
    """Write `payload` with its checksum to `path`, atomically, indented; the lists under the
    keys `rows` one compact item per line (json's indenting encoder is pure Python: a policy
    of 10^6 states took 10 s to indent, 1.5 s this way)."""
    data = with_checksum(payload)
    if not rows:
        atomic_write_text(Path(path), json.dumps(data, indent=1, sort_keys=True) + "\n")
        return
    fields = []
    for key in sorted(data):
        value = data[key]
        if key in rows and value:
            items = ",\n  ".join(map(_ROW.encode, value))
            text = f"[\n  {items}\n ]"
        else:
            text = json.dumps(value, indent=1, sort_keys=True).replace("\n", "\n ")
        fields.append(f" {json.dumps(key)}: {text}")
    atomic_write_text(Path(path), "{\n" + ",\n".join(fields) + "\n}\n")


_ROW = json.JSONEncoder(sort_keys=True)  # one item of a row list, compact (json's C encoder)


def has_format(path: str | Path, fmt: str) -> bool:
    """Whether `path` is a JSON object whose `format` is `fmt` (a file `save_checked_json` wrote
    in that format, perhaps of another version or corrupted since): a file a writer of `fmt` may
    replace without `--force` (`hrc_drake.paths.check_output_path`)."""
    try:
        with open(path, "rb") as f:
            payload = json.loads(f.read())
    except (OSError, ValueError):  # unreadable, not UTF-8, not JSON
        return False
    return isinstance(payload, dict) and payload.get("format") == fmt


def said(fix: str | Callable[[], str]) -> str:
    """A fix given as text, or as a function that makes the text (when making it costs, e.g.
    reading the file again, only a file with a problem pays for it)."""
    return fix() if callable(fix) else fix


def load_checked_json(
    path: str | Path,
    *,
    what: str,
    fmt: str,
    version: int,
    fix: str | Callable[[], str],
    error: type[Exception],
    older: Mapping[int, str] | None = None,
    readable: Collection[int] = (),
) -> dict[str, Any]:
    """The payload of a file written by `save_checked_json` (without its checksum).

    `what` names the kind of file in messages ("policy file"), `fix` says how to make a good
    one (or a function that says it, called only when a problem is found); problems raise
    `error`. `older` says, per older version, what it lacks (the message of a file of that
    version says it); `readable`, the versions besides `version` that are read
    as they are (the payload's `version` says which).
    """
    path = Path(path)
    if path.is_dir():
        raise error(
            f"{what} {path} is a directory; pass a file (e.g. {path / 'file.json'}); {said(fix)}"
        )
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise error(f"{what} {path} not found; {said(fix)}") from None
    except (OSError, UnicodeDecodeError) as err:
        reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        raise error(f"{what} {path} cannot be read ({reason}); {said(fix)}") from None
    try:
        with gc_paused():
            payload = json.loads(text)
    except json.JSONDecodeError as err:
        raise error(f"{what} {path} is corrupted (not JSON: {err}); {said(fix)}") from None
    del text  # not kept beside the payload while it is checked (a policy file: 80 MB at 10^6)
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise error(f"{path} is not an hrc_drake {what}; {said(fix)}")
    if payload.get("version") != version and payload.get("version") not in readable:
        lacks = (older or {}).get(payload.get("version"))
        lacks = f" ({lacks})" if lacks else ""
        raise error(
            f"{what} {path} has format version {payload.get('version')!r}{lacks}; this "
            f"hrc_drake reads version {version}; {said(fix)}"
        )
    stored = payload.pop("checksum", None)
    if stored != checksum(payload):
        raise error(f"{what} {path} is corrupted (checksum mismatch); {said(fix)}")
    return payload


def first_infeasible(space, pairs) -> str | None:
    """The first (state, task) of `pairs` that is not a feasible task of `space`, described;
    None when every pair is feasible."""
    for state, task in pairs:
        try:
            index = space.index(state)
        except KeyError:
            return f"names {list(state)}, not a state of {space.spec.name!r}"
        if task not in {t for t, _ in space.tasks(index)}:
            return f"gives task {task!r} in {list(state)}, where it is not feasible"
    return None


def check_made_for(
    what: str, made_name: str, made_hash: str, spec, fix: str, error: type[Exception]
) -> None:
    """Raise `error` unless a file made for the spec `made_name`/`made_hash` fits `spec`."""
    if spec.spec_hash != made_hash:
        raise error(
            f"{what} was made for assembly {made_name!r} (spec hash {made_hash}), not for "
            f"{spec.name!r} from {spec.source} (hash {spec.spec_hash}); {fix}"
        )
