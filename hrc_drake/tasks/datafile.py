"""Versioned, checksummed JSON files (policies, cost tables): one writer and one reader.

A file is a JSON object with `format`, `version` and a `checksum` of the rest; it is written
atomically. Reading refuses, with a one-line error that ends with the fix, a directory, a
missing or unreadable file, a file that is not JSON, another format, another version, and a
checksum that does not match (a file edited or cut short).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hrc_drake.atomic import atomic_write_text


def checksum(payload: Mapping[str, Any]) -> str:
    """SHA-256 of the payload's canonical JSON."""
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def with_checksum(payload: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of `payload` with its `checksum` added."""
    out = dict(payload)
    out["checksum"] = checksum(payload)
    return out


def save_checked_json(path: str | Path, payload: Mapping[str, Any]) -> None:
    """Write `payload` with its checksum to `path`, atomically."""
    text = json.dumps(with_checksum(payload), indent=1, sort_keys=True) + "\n"
    atomic_write_text(Path(path), text)


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


def load_checked_json(
    path: str | Path,
    *,
    what: str,
    fmt: str,
    version: int,
    fix: str,
    error: type[Exception],
    older: Mapping[int, str] | None = None,
) -> dict[str, Any]:
    """The payload of a file written by `save_checked_json` (without its checksum).

    `what` names the kind of file in messages ("policy file"), `fix` says how to make a good
    one; problems raise `error`. `older` says, per older version, what it lacks (the message of
    a file of that version says it).
    """
    path = Path(path)
    if path.is_dir():
        raise error(f"{what} {path} is a directory; pass a file (e.g. {path / 'file.json'}); {fix}")
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise error(f"{what} {path} not found; {fix}") from None
    except (OSError, UnicodeDecodeError) as err:
        reason = err.strerror if isinstance(err, OSError) and err.strerror else str(err)
        raise error(f"{what} {path} cannot be read ({reason}); {fix}") from None
    try:
        payload = json.loads(text)
    except json.JSONDecodeError as err:
        raise error(f"{what} {path} is corrupted (not JSON: {err}); {fix}") from None
    if not isinstance(payload, dict) or payload.get("format") != fmt:
        raise error(f"{path} is not an hrc_drake {what}; {fix}")
    if payload.get("version") != version:
        lacks = (older or {}).get(payload.get("version"))
        lacks = f" ({lacks})" if lacks else ""
        raise error(
            f"{what} {path} has format version {payload.get('version')!r}{lacks}; this "
            f"hrc_drake reads version {version}; {fix}"
        )
    stored = payload.pop("checksum", None)
    if stored != checksum(payload):
        raise error(f"{what} {path} is corrupted (checksum mismatch); {fix}")
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
