"""Per-state listings (`hrc-drake states`, `policy`, `check-policy`), written as they go.

A listing of a million states is never held whole: states are taken in chunks, their sequences
rebuilt from the `StateSpace`'s flat arrays (`StateSpace.token_paths`), and what depends only on
the configuration (its tokens, kind, feasible tasks) is rendered once per configuration. The
JSON is the text `json.dump(rows, indent=1)` writes for the list of every row, byte for byte.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from typing import TextIO

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.tokens import UNDO

CHUNK = 1 << 15  # states per chunk: a few MB of sequences, however large the space


def _json_list(items: Iterable[str]) -> str:
    """A list of strings as a value of a row of a top-level list, indented as `indent=1`."""
    items = list(items)
    if not items:
        return "[]"
    return "[\n" + ",\n".join("   " + json.dumps(x) for x in items) + "\n  ]"


def write_json_list(out: TextIO, rows: Iterable[str]) -> None:
    """`json.dump(list, out, indent=1)` and a newline, from rows already rendered."""
    out.write("[")
    first = True
    for row in rows:
        out.write(("\n" if first else ",\n") + row)
        first = False
    out.write("\n]\n" if not first else "]\n")


def chunks(space: StateSpace, states: np.ndarray) -> Iterator[tuple[np.ndarray, list[list[int]]]]:
    """`states` in chunks of `CHUNK`, each with the sequences of its states (lists of token
    indices)."""
    for lo in range(0, len(states), CHUNK):
        part = states[lo : lo + CHUNK]
        rows = zip(space.token_paths(part).tolist(), space.depth[part].tolist(), strict=True)
        yield part, [row[:d] for row, d in rows]


def sequences(space: StateSpace, states: np.ndarray) -> Iterator[list[str]]:
    """The sequences of `states` (token lists), chunk by chunk."""
    tokens = space.tokens
    for _, paths in chunks(space, states):
        for path in paths:
            yield [tokens[t] for t in path]


class _Sequences:
    """Sequences of token indices rendered as `_json_list` renders them, token texts once."""

    def __init__(self, space: StateSpace):
        self.items = ["   " + json.dumps(t) for t in space.tokens]
        self.tokens = space.tokens

    def json(self, path: list[int]) -> str:
        if not path:
            return "[]"
        return "[\n" + ",\n".join([self.items[t] for t in path]) + "\n  ]"

    def words(self, path: list[int]) -> list[str]:
        return [self.tokens[t] for t in path]


def listing_order(space: StateSpace) -> np.ndarray:
    """State ids in the order `states` lists them: by name when every name is a number
    (Table 1's numbers for the flange case; ids + 1 without `state_names`), else by id."""
    if not space.spec.state_names:
        return np.arange(space.n_states)
    names = [space.name(s) for s in range(space.n_states)]  # labelled specs are small
    if not all(n.isdigit() for n in names):
        return np.arange(space.n_states)
    return np.array(sorted(range(space.n_states), key=lambda s: int(names[s])), dtype=np.int64)


class _ByConfiguration:
    """What a state's configuration decides, computed once per configuration: its tokens
    (sorted), its kind and its feasible tasks (placements depend on what is in place, not on
    the order; undo on every state but the start, the only empty one)."""

    def __init__(self, space: StateSpace):
        _, first, self.of_state = np.unique(space.mask, return_index=True, return_inverse=True)
        self.configuration, self.kind, self.tasks, self.actions = [], [], [], []
        for s in first.tolist():
            tasks = [t for t, _ in space.tasks(s)]
            self.configuration.append(sorted(space.configuration(s)))
            self.kind.append(space.state_kind(s).key)
            self.tasks.append(tasks)
            self.actions.append(sorted({space.action_label(t) for t in tasks}))


def _names(space: StateSpace) -> Callable[[int, list[int]], str]:
    """A state's name (`StateSpace.name`) from its id and its path of token indices."""
    if not space.spec.state_names:
        return lambda s, _path: str(s + 1)
    labels, tokens = space.spec.state_names, space.tokens
    return lambda s, path: labels.get(" ".join(tokens[t] for t in path), str(s + 1))


def state_rows_json(space: StateSpace, fewest: np.ndarray) -> Iterator[str]:
    """The rows of `hrc-drake states --json`, rendered, in `listing_order`."""
    by = _ByConfiguration(space)
    # Everything between the sequence and the number of tasks, once per configuration.
    middle = [
        f',\n  "configuration": {_json_list(c)},\n  "kind": {json.dumps(k)},\n'
        f'  "tasks": {_json_list(t)},\n  "actions": {_json_list(a)},\n  "tasks_to_finish": '
        for c, k, t, a in zip(by.configuration, by.kind, by.tasks, by.actions, strict=True)
    ]
    name, render = _names(space), _Sequences(space)
    for part, paths in chunks(space, listing_order(space)):
        configs, best = by.of_state[part].tolist(), fewest[part].tolist()
        for s, path, c, b in zip(part.tolist(), paths, configs, best, strict=True):
            yield (
                f' {{\n  "name": {json.dumps(name(s, path))},\n  "sequence": '
                f"{render.json(path)}{middle[c]}{b}\n }}"
            )


def state_rows_text(space: StateSpace, fewest: np.ndarray) -> Iterator[str]:
    """The lines of `hrc-drake states` (after its header), in `listing_order`."""
    by = _ByConfiguration(space)
    kinds = [k.replace("_", " ") for k in by.kind]
    tasks = [", ".join(t) for t in by.tasks]
    name, render = _names(space), _Sequences(space)
    for part, paths in chunks(space, listing_order(space)):
        configs, best = by.of_state[part].tolist(), fewest[part].tolist()
        for s, path, c, b in zip(part.tolist(), paths, configs, best, strict=True):
            shown = " ".join(render.words(path)) or "(empty base)"
            yield f"{name(s, path):>4}  {shown:<20} {kinds[c]:<10} {b:>9}  {tasks[c]}"


_NONE, _UNDO = -1, -2  # the task of a policy row: none (terminal), undo, or a token index


def _policy_rows(space: StateSpace, next_state: np.ndarray):
    """(path, kind key, task) of every state, by id (task: a token index, `_UNDO` or
    `_NONE`)."""
    kinds = {int(k): k.key for k in StateKind}
    for part, paths in chunks(space, np.arange(space.n_states)):
        nxt = next_state[part]
        undo = (nxt >= 0) & (nxt == space.parent[part]) & (part > 0)
        task = np.where(nxt >= 0, space.last[np.maximum(nxt, 0)], _NONE)
        task[undo] = _UNDO
        for path, k, t in zip(paths, space.kind[part].tolist(), task.tolist(), strict=True):
            yield path, kinds[k], t


def policy_rows_json(space: StateSpace, next_state: np.ndarray) -> Iterator[str]:
    """The rows of `hrc-drake policy --json`, rendered, by state id: per state its sequence,
    kind, the task the policy proposes (null: none) and the sequence it leads to."""
    render = _Sequences(space)
    kinds = {k.key: json.dumps(k.key) for k in StateKind}
    tasks = {t: json.dumps(x) for t, x in [*enumerate(space.tokens), (_UNDO, UNDO), (_NONE, None)]}
    for path, kind, t in _policy_rows(space, next_state):
        shown = render.json(path)
        if t == _NONE:
            after = "null"
        else:
            after = render.json(path[:-1]) if t == _UNDO else render.json([*path, t])
        yield (
            f' {{\n  "sequence": {shown},\n  "kind": {kinds[kind]},\n'
            f'  "task": {tasks[t]},\n  "next": {after}\n }}'
        )


def policy_rows_text(space: StateSpace, next_state: np.ndarray) -> Iterator[str]:
    """The lines of `hrc-drake policy`, by state id."""
    tokens = space.tokens
    names = {_UNDO: UNDO, _NONE: "-", **dict(enumerate(tokens))}
    for path, kind, t in _policy_rows(space, next_state):
        shown = " ".join(tokens[t] for t in path) or "(start)"
        yield f"{shown:<16} {kind.replace('_', ' '):<10} -> {names[t]}"


__all__ = [
    "chunks",
    "listing_order",
    "policy_rows_json",
    "policy_rows_text",
    "sequences",
    "state_rows_json",
    "state_rows_text",
    "write_json_list",
]
