"""Policies: state -> next task, with versioned, checksummed, atomically written files.

A policy file is JSON::

    {"format": "hrc_drake.policy", "version": 1,
     "spec": {"name": ..., "hash": ...},          # the assembly it was made for
     "method": "exact" | "q-learning/paper" | ..., "meta": {...},
     "entries": [[[task, ...], next_task], ...],  # every non-terminal state
     "checksum": sha256 of the canonical JSON of everything above}
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hrc_drake.paths import OutputKind, fresh_name
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.datafile import (
    check_made_for,
    first_infeasible,
    gc_paused,
    has_format,
    load_checked_json,
    save_checked_json,
)
from hrc_drake.tasks.graph import StateSpace, UnknownStateError
from hrc_drake.tasks.mdp import SequenceMDP
from hrc_drake.tasks.tokens import UNDO

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
    tasks = [*space.tokens, UNDO]  # edge_task -1 (undo) picks the last
    task = np.where(choice >= 0, mdp.edge_task[np.maximum(choice, 0)], -2).tolist()
    tokens, parent, last = space.tokens, space.parent.tolist(), space.last.tolist()
    # Each sequence is its parent's plus one task: built in id order (parents come first),
    # not walked up from every state.
    sequences: list[tuple[str, ...]] = [()] * space.n_states
    with gc_paused():
        for s in range(space.n_states):
            seq = sequences[s] = sequences[parent[s]] + (tokens[last[s]],) if s else ()
            if task[s] != -2:
                table[seq] = tasks[task[s]]
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
    with gc_paused():
        payload = _payload(policy)
    save_checked_json(path, payload, rows=("entries", "terminal"))


def load_policy(path: str | Path, space: StateSpace) -> Policy:
    """Load a policy file made for `space`'s spec; PolicyFileError with the fix if unusable."""
    path = Path(path)

    def fix() -> str:  # reads the file again: only when it has a problem
        return new_policy_hint(path)

    if path.is_dir():
        raise PolicyFileError(
            f"policy file {path} is a directory; pass a policy file (e.g. {path / 'policy.json'}"
            f"), made with `hrc-drake solve --out {path / 'policy.json'}` or `hrc-drake train`"
        )
    payload = load_checked_json(
        path, what="policy file", fmt=FORMAT, version=VERSION, fix=fix, error=PolicyFileError
    )
    try:
        with gc_paused():
            policy = _policy_of(payload, {t: t for t in (*space.tokens, UNDO)})
    except (KeyError, TypeError, ValueError) as err:
        raise PolicyFileError(
            f"policy file {path} is corrupted (bad entry: {err}); {fix()}"
        ) from None
    policy.matches(space.spec)
    _, targets = _entry_targets(space, policy)
    bad = np.flatnonzero(targets < 0)
    if len(bad):
        # The first bad entry in the file's order, said as `first_infeasible` says it.
        state, task = next(itertools.islice(policy.table.items(), int(bad[0]), None))
        problem = first_infeasible(space, [(state, task)])
        raise PolicyFileError(f"policy file {path} {problem}; {fix()}")
    return policy


def _policy_of(payload: dict[str, Any], names: Mapping[str, str]) -> Policy:
    """The Policy of a parsed file. Its rows are freed as they enter the table, and task names
    point at the spec's own strings (`names`), not at one string per token of the file: at
    10^6 states the parse and the table are not held side by side."""

    def consumed(rows: list) -> Iterator:
        for i in range(len(rows)):
            row, rows[i] = rows[i], None
            yield row

    table = {tuple(map(names.get, k, k)): names.get(v, v) for k, v in consumed(payload["entries"])}
    terminal = frozenset(tuple(map(names.get, t, t)) for t in consumed(payload.get("terminal", [])))
    return Policy(
        spec_name=payload["spec"]["name"],
        spec_hash=payload["spec"]["hash"],
        method=payload["method"],
        table=table,
        meta=payload.get("meta", {}),
        terminal=terminal,
    )


def _entry_targets(space: StateSpace, policy: Policy) -> tuple[np.ndarray, np.ndarray]:
    """Per entry of `policy.table` (in its order): the state id (-1: not a state) and the state
    its task leads to when done as proposed (-1: not a state, or the task is not feasible)."""
    ids = space.indices(list(policy.table))
    tasks = space.token_codes(policy.table.values(), len(policy.table))
    return ids, space.successors(ids, tasks)


def next_states(space: StateSpace, policy: Policy) -> np.ndarray:
    """Per state id, the state the policy's task leads to when the operator does it (no
    deviation, no mistake); -1 where the policy proposes nothing (a terminal state, or a state
    the policy does not name) or names an infeasible task. The policy as a functional graph
    over state ids, for vectorised checks (`hrc_drake.tasks.policy_check`)."""
    ids, targets = _entry_targets(space, policy)
    out = np.full(space.n_states, -1, dtype=np.int64)
    ok = (ids >= 0) & (targets >= 0)
    out[ids[ok]] = targets[ok]
    return out
