"""Operator profiles: what one person does when the robot proposes, kept across assemblies.

A profile is an `OnlineOperatorModel` (Dirichlet counts of the task performed per state and
proposal) saved to a file, so that the same person working the cell all day is not a stranger at
every run: `mpc` starts from it (`make_decider(..., model=profile.model)`), and a run adds what
the person did (`learn`). The functions here are what `hrc-drake simulate --operator-profile
FILE` calls: `load_or_new_profile` before the run (to refuse an unusable file before any work),
`update_profile` after it. The update is a read-modify-write under an exclusive lock on a file
beside the profile (`FILE.lock`, `fcntl.flock`), so that runs ending at the same time each add
their session: saving what each loaded before its run would keep only the last.

A profile file is JSON, written atomically (`hrc_drake.tasks.datafile`)::

    {"format": "hrc_drake.operator_profile", "version": 1,
     "spec_name": "flange", "spec_hash": "...",
     "priors": {"follow": 4.0, "other": 0.05, "pool": 1.0},
     "assemblies": 12,                       # runs learned from
     "observations": [{"state": [], "proposed": "F1", "performed": "S23", "count": 3}, ...],
     "checksum": sha256 of the canonical JSON of everything above}

A file that cannot be read, is corrupted, of another version, or made for another assembly is
refused with a one-line `ProfileError` naming the fix; observations that are not feasible in the
assembly are refused too.
"""

from __future__ import annotations

import fcntl
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hrc_drake.tasks.datafile import (
    check_made_for,
    first_infeasible,
    load_checked_json,
    save_checked_json,
)
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.operator_model import OnlineOperatorModel

FORMAT = "hrc_drake.operator_profile"
VERSION = 1


class ProfileError(ValueError):
    """An operator profile that cannot be used: unreadable, corrupted, or for another spec."""


@dataclass
class OperatorProfile:
    """One operator's model of answers for one assembly, and how many assemblies taught it."""

    model: OnlineOperatorModel
    assemblies: int = 0

    @property
    def space(self) -> StateSpace:
        """The state space the profile was made for."""
        return self.model.space


def new_profile(space: StateSpace, **priors: float) -> OperatorProfile:
    """An empty profile for `space` (the model's default priors unless given)."""
    return OperatorProfile(OnlineOperatorModel(space, **priors))


def learn(profile: OperatorProfile, tasks: Iterable[Any]) -> OperatorProfile:
    """Add one assembly's tasks to the profile: records with `state`, `proposed` and what was
    done — `observed` (the cell's `TaskRecord`: what the cell saw) or `performed`. Returns the
    profile (changed in place)."""
    for task in tasks:
        done = getattr(task, "observed", None) or task.performed
        profile.model.update(tuple(task.state), task.proposed, done)
    profile.assemblies += 1
    return profile


def _fix(path: Path) -> str:
    return f"delete {path} to start a new profile, or give another file to --operator-profile"


def save_profile(profile: OperatorProfile, path: str | Path) -> None:
    """Write the profile to `path` atomically, with the spec's hash and a checksum."""
    model, spec = profile.model, profile.space.spec
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "spec_name": spec.name,
        "spec_hash": spec.spec_hash,
        "priors": {"follow": model.follow_prior, "other": model.other_prior, "pool": model.pool},
        "assemblies": profile.assemblies,
        "observations": [
            {"state": list(state), "proposed": proposed, "performed": performed, "count": count}
            for state, proposed, performed, count in model.records()
        ],
    }
    save_checked_json(path, payload)


def _count(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{what} must be a number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{what} must be > 0, got {value!r}")
    return float(value)


def load_profile(path: str | Path, space: StateSpace) -> OperatorProfile:
    """The profile in `path`, made for `space`'s assembly; ProfileError naming the problem and
    the fix otherwise (missing, unreadable, corrupted, another version or spec, observations
    that are not feasible)."""
    path = Path(path)
    fix = _fix(path)
    payload = load_checked_json(
        path, what="operator profile", fmt=FORMAT, version=VERSION, fix=fix, error=ProfileError
    )
    try:
        check_made_for(
            "operator profile", str(payload["spec_name"]), str(payload["spec_hash"]),
            space.spec, fix, ProfileError,
        )  # fmt: skip
    except ProfileError as err:
        raise ProfileError(f"{path}: {err}") from None
    try:
        priors = payload["priors"]
        model = OnlineOperatorModel(
            space, float(priors["follow"]), float(priors["other"]), float(priors["pool"])
        )
        rows = [
            (tuple(o["state"]), str(o["proposed"]), str(o["performed"]),
             _count(o["count"], f"observation {i} count"))
            for i, o in enumerate(payload["observations"])
        ]  # fmt: skip
        assemblies = int(payload["assemblies"])
    except (KeyError, TypeError, ValueError) as err:
        raise ProfileError(f"operator profile {path} is corrupted ({err}); {fix}") from None
    pairs = [(state, t) for state, proposed, performed, _ in rows for t in (proposed, performed)]
    problem = first_infeasible(space, pairs)
    if problem is not None:
        raise ProfileError(f"operator profile {path} {problem}; {fix}")
    for state, proposed, performed, count in rows:
        model.update(state, proposed, performed, count)
    return OperatorProfile(model, assemblies)


def lock_path(path: str | Path) -> Path:
    """The lock file of the profile in `path`: beside it, `<name>.lock`. It is locked, never
    written, and left in place (removing it could let two runs lock different files)."""
    path = Path(path)
    return path.with_name(path.name + ".lock")


def update_profile(path: str | Path, space: StateSpace, tasks: Iterable[Any]) -> OperatorProfile:
    """Add one assembly's `tasks` (as for `learn`) to the profile in `path` (a new one for
    `space` if there is none) and save it; returns the saved profile. The file is read, learned
    into and written while holding an exclusive lock on `lock_path(path)`, so concurrent updates
    follow each other and none is lost; the write stays atomic for readers that do not lock.
    ProfileError as for `load_profile`."""
    path = Path(path)
    tasks = list(tasks)  # read before the lock is taken: the lock is held for file work only
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path(path), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
        profile = learn(load_or_new_profile(path, space), tasks)
        save_profile(profile, path)
    return profile


def load_or_new_profile(path: str | Path, space: StateSpace) -> OperatorProfile:
    """The profile in `path` if the file exists (`load_profile`: refused when it is unusable),
    else a new one for `space`."""
    path = Path(path)
    if not path.exists():
        return new_profile(space)
    return load_profile(path, space)


__all__ = [
    "OperatorProfile",
    "ProfileError",
    "learn",
    "load_or_new_profile",
    "load_profile",
    "lock_path",
    "new_profile",
    "save_profile",
    "update_profile",
]
