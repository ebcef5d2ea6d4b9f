"""Policies: state -> next task, with versioned, checksummed, atomically written files.

A policy file is JSON::

    {"format": "hrc_drake.policy", "version": 1,
     "spec": {"name": ..., "hash": ...},          # the assembly it was made for
     "method": "exact" | "q-learning/paper" | ..., "meta": {...},
     "entries": [[[task, ...], next_task], ...],  # every non-terminal state
     "checksum": sha256 of the canonical JSON of everything above}
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hrc_drake.paths import OutputKind, fresh_name
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.datafile import (
    check_made_for,
    first_infeasible,
    has_format,
    load_checked_json,
    save_checked_json,
)
from hrc_drake.tasks.graph import StateSpace, UnknownStateError
from hrc_drake.tasks.mdp import SequenceMDP

FORMAT = "hrc_drake.policy"
VERSION = 1


class PolicyFileError(ValueError):
    """A policy file that cannot be used: corrupted, of another version, or another spec."""


def is_policy_file(path: str | Path) -> bool:
    """Whether `path` is a policy file (its `format` says so; it may be of another version or
    corrupted): `solve` and `train` replace it without `--force`."""
    return has_format(path, FORMAT)


POLICY_FILE = OutputKind("policy file", is_policy_file, "policy.json")


def new_policy_hint(path: str | Path) -> str:
    """How to make a policy for `path`'s use: `solve --out PATH` when writing there replaces
    nothing but a policy; else a fresh name beside it, never a file that is not a policy."""
    path = Path(path)
    fresh = not path.exists() or is_policy_file(path)
    out = path if fresh else fresh_name(path, "policy", ".json")
    return f"make a new one with `hrc-drake solve --out {out}` (or `hrc-drake train`)"


@dataclass(frozen=True)
class Policy:
    """The robot's proposal for every state of one assembly."""

    spec_name: str
    spec_hash: str
    method: str
    table: Mapping[tuple[str, ...], str]
    meta: Mapping[str, Any] = field(default_factory=dict)
    terminal: frozenset[tuple[str, ...]] = frozenset()

    def next_task(self, state: tuple[str, ...]) -> str | None:
        """The task to propose in `state`; None in a terminal state.

        Raises UnknownStateError (a KeyError) if `state` is not a state of this assembly.
        """
        try:
            return self.table[state]
        except KeyError:
            if state in self.terminal:
                return None
            raise UnknownStateError(_NamedSpec(self.spec_name), tuple(state)) from None

    def matches(self, spec: AssemblySpec) -> None:
        """Raise PolicyFileError unless this policy was made for `spec`."""
        fix = (
            f"make a new one with `hrc-drake solve --assembly {spec.source} --out FILE` or `train`"
        )
        check_made_for("policy", self.spec_name, self.spec_hash, spec, fix, PolicyFileError)


@dataclass(frozen=True)
class _NamedSpec:
    name: str
    source: str = "the policy file"


def policy_from_choices(
    mdp: SequenceMDP, choice: np.ndarray, method: str, meta: Mapping[str, Any] | None = None
) -> Policy:
    """A Policy from one chosen edge per state (-1 where the episode ends)."""
    space = mdp.space
    table, terminal = {}, set()
    for s in range(space.n_states):
        seq = space.sequence(s)
        if choice[s] >= 0:
            table[seq] = mdp.task_name(int(choice[s]))
        else:
            terminal.add(seq)
    return Policy(
        spec_name=space.spec.name,
        spec_hash=space.spec.spec_hash,
        method=method,
        table=table,
        meta=dict(meta or {}),
        terminal=frozenset(terminal),
    )


def _payload(policy: Policy) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "spec": {"name": policy.spec_name, "hash": policy.spec_hash},
        "method": policy.method,
        "meta": dict(policy.meta),
        "entries": sorted([list(k), v] for k, v in policy.table.items()),
        "terminal": sorted(list(t) for t in policy.terminal),
    }


def save_policy(policy: Policy, path: str | Path) -> None:
    """Save atomically, with the spec hash and a checksum of the content."""
    save_checked_json(path, _payload(policy))


def load_policy(path: str | Path, space: StateSpace) -> Policy:
    """Load a policy file made for `space`'s spec; PolicyFileError with the fix if unusable."""
    path = Path(path)
    fix = new_policy_hint(path)
    if path.is_dir():
        raise PolicyFileError(
            f"policy file {path} is a directory; pass a policy file (e.g. {path / 'policy.json'}"
            f"), made with `hrc-drake solve --out {path / 'policy.json'}` or `hrc-drake train`"
        )
    payload = load_checked_json(
        path, what="policy file", fmt=FORMAT, version=VERSION, fix=fix, error=PolicyFileError
    )
    try:
        policy = Policy(
            spec_name=payload["spec"]["name"],
            spec_hash=payload["spec"]["hash"],
            method=payload["method"],
            table={tuple(k): v for k, v in payload["entries"]},
            meta=payload.get("meta", {}),
            terminal=frozenset(tuple(t) for t in payload.get("terminal", [])),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise PolicyFileError(
            f"policy file {path} is corrupted (bad entry: {err}); {fix}"
        ) from None
    policy.matches(space.spec)
    problem = first_infeasible(space, policy.table.items())
    if problem is not None:
        raise PolicyFileError(f"policy file {path} {problem}; {fix}")
    return policy
