"""From an assembly spec to its states: every feasible sequence of tasks.

States are generated breadth-first, one depth at a time, with the configuration of each state
held as a bitmask over the spec's placement tokens, so that a level of any size is expanded by a
few numpy operations per token. The result is a `StateSpace` of flat arrays (what solvers and
learners use at scale); `StateSpace.to_networkx()` gives the graph users see and plot.

State ids are canonical: by depth, then by parent, then by task in the spec's token order.
"""

from __future__ import annotations

import enum
import itertools
from dataclasses import dataclass
from functools import cached_property

import networkx as nx
import numpy as np

from hrc_drake.tasks.assembly import BASE, AssemblySpec, SpecError
from hrc_drake.tasks.tokens import UNDO

MAX_TOKENS = 64


class StateKind(enum.IntEnum):
    """What a state is, in the paper's terms."""

    START = 0
    NORMAL = 1
    TERMINAL = 2  # complete and correct
    WRONG = 3  # complete, a part in a wrong place: only disassembly
    DEAD_END = 4  # incomplete, no assembly task left: only disassembly

    @property
    def label(self) -> str:
        """Lower-case name with spaces, for tables and plots people read (``dead end``)."""
        return self.name.lower().replace("_", " ")

    @property
    def key(self) -> str:
        """snake_case name for JSON and other machine-read output (``dead_end``)."""
        return self.name.lower()


@dataclass(frozen=True)
class TokenTable:
    """Per-token bitmasks that decide which tasks are feasible from a configuration."""

    tokens: tuple[str, ...]
    part: np.ndarray  # index of the token's part type
    mount: np.ndarray  # index of the token's mount (part on base / on a host)
    slots: tuple[tuple[int, ...], ...]
    bit: np.ndarray  # uint64, 1 << i
    conflict: np.ndarray  # tokens that use the same slot or seat (itself included)
    requires: np.ndarray  # host tokens one of which must be present (0: none needed)
    mount_mask: np.ndarray  # per mount: tokens of that mount
    mount_count: np.ndarray
    part_mask: np.ndarray  # per part type: its tokens
    part_count: np.ndarray


def _token_table(spec: AssemblySpec) -> TokenTable:
    placements = spec.placements()
    if len(placements) > MAX_TOKENS:
        raise SpecError(
            f"assembly spec {spec.source}: {len(placements)} placement tasks; at most "
            f"{MAX_TOKENS} are supported (fewer slots or fewer mounts)"
        )
    n = len(placements)
    symbols = [p.symbol for p in spec.parts]
    mounts = list(spec.mounts)
    part = np.array([symbols.index(m.part) for _, m, _ in placements], dtype=np.int64)
    mount = np.array([mounts.index(m) for _, m, _ in placements], dtype=np.int64)
    bit = np.array([1 << i for i in range(n)], dtype=np.uint64)
    conflict = np.zeros(n, dtype=np.uint64)
    requires = np.zeros(n, dtype=np.uint64)
    for i, (_, mi, si) in enumerate(placements):
        for j, (_, mj, sj) in enumerate(placements):
            on_base = mi.on == BASE and mj.on == BASE
            same_seat = mi.on != BASE and mi.on == mj.on and si == sj
            if (on_base and set(si) & set(sj)) or same_seat:
                conflict[i] |= bit[j]
            if mi.on != BASE and mj.on == BASE and mj.part == mi.on and si[0] in sj:
                requires[i] |= bit[j]
    mount_mask = np.zeros(len(mounts), dtype=np.uint64)
    part_mask = np.zeros(len(symbols), dtype=np.uint64)
    for i in range(n):
        mount_mask[mount[i]] |= bit[i]
        part_mask[part[i]] |= bit[i]
    return TokenTable(
        tokens=tuple(t for t, _, _ in placements),
        part=part,
        mount=mount,
        slots=tuple(s for _, _, s in placements),
        bit=bit,
        conflict=conflict,
        requires=requires,
        mount_mask=mount_mask,
        mount_count=np.array([m.count for m in mounts], dtype=np.int64),
        part_mask=part_mask,
        part_count=np.array([p.count for p in spec.parts], dtype=np.int64),
    )


def token_table(spec: AssemblySpec) -> TokenTable:
    """The per-token bitmasks of `spec`: which tokens share a slot or seat, which host tokens
    one must sit on, the tokens of each mount and part type and their counts."""
    return _token_table(spec)


def _popcount(x: np.ndarray) -> np.ndarray:
    return np.bitwise_count(x).astype(np.int64)


def _feasible(spec: AssemblySpec, table: TokenTable, masks: np.ndarray) -> np.ndarray:
    """Boolean (len(masks), n_tokens): which placement tasks are feasible from each mask."""
    n = len(table.tokens)
    mount_full = np.stack(
        [
            _popcount(masks & table.mount_mask[g]) >= table.mount_count[g]
            for g in range(len(table.mount_count))
        ],
        axis=1,
    )
    part_done = np.stack(
        [
            _popcount(masks & table.part_mask[p]) >= table.part_count[p]
            for p in range(len(table.part_count))
        ],
        axis=1,
    )
    # Sub-assemblies to complete first: seats on a placed host that still await their parts.
    pending = np.zeros_like(masks)
    symbols = [p.symbol for p in spec.parts]
    for host in spec.complete_first:
        h = symbols.index(host)
        per_instance = sum(m.count for m in spec.mounts if m.on == host) // spec.parts[h].count
        for i in np.flatnonzero(table.part == h):
            seats = np.uint64(0)
            for j in range(n):
                if table.requires[j] & table.bit[i]:
                    seats |= table.bit[j]
            waiting = ((masks & table.bit[i]) != 0) & (_popcount(masks & seats) < per_instance)
            pending |= np.where(waiting, seats, np.uint64(0))
    feasible = np.empty((len(masks), n), dtype=bool)
    for t in range(n):
        ok = (masks & table.conflict[t]) == 0
        if table.requires[t]:
            ok &= (masks & table.requires[t]) != 0
        ok &= ~mount_full[:, table.mount[t]]
        ok &= (pending == 0) | ((pending & table.bit[t]) != 0)
        for a, b in spec.before:
            if spec.parts[table.part[t]].symbol == b:
                ok &= part_done[:, symbols.index(a)]
        feasible[:, t] = ok
    return feasible


def _kinds(spec: AssemblySpec, table: TokenTable, masks: np.ndarray, has_task: np.ndarray):
    complete = _popcount(masks) == spec.total_parts
    correct = np.ones(len(masks), dtype=bool)
    symbols = [p.symbol for p in spec.parts]
    for rule in spec.goal.min_gap:
        a, b = (symbols.index(x) for x in rule.parts)
        for i in np.flatnonzero(table.part == a):
            near = np.uint64(0)
            for j in np.flatnonzero(table.part == b):
                gap = min(abs(x - y) for x in table.slots[i] for y in table.slots[j])
                if i != j and gap < rule.slots:
                    near |= table.bit[j]
            correct &= ~(((masks & table.bit[i]) != 0) & ((masks & near) != 0))
    if spec.goal.correct is not None:
        index = {t: i for i, t in enumerate(table.tokens)}
        allowed = np.array(
            [sum(int(table.bit[index[t]]) for t in c) for c in spec.goal.correct],
            dtype=np.uint64,
        )
        correct &= np.isin(masks, allowed)
    kind = np.full(len(masks), StateKind.NORMAL, dtype=np.int8)
    kind[complete & correct] = StateKind.TERMINAL
    kind[complete & ~correct] = StateKind.WRONG
    kind[~complete & ~has_task] = StateKind.DEAD_END
    kind[0] = StateKind.START
    return kind


@dataclass(frozen=True, eq=False)
class StateSpace:
    """Every state of an assembly, as flat arrays indexed by state id (0 = start).

    Children of a state are contiguous ids ``first_child[s] : first_child[s] + n_children[s]``.
    """

    spec: AssemblySpec
    table: TokenTable
    parent: np.ndarray  # int64, -1 for the start
    last: np.ndarray  # int64 token index of the last task, -1 for the start
    depth: np.ndarray
    mask: np.ndarray  # uint64 configuration
    kind: np.ndarray  # int8 StateKind
    first_child: np.ndarray
    n_children: np.ndarray

    @property
    def n_states(self) -> int:
        """Number of states."""
        return len(self.parent)

    @property
    def tokens(self) -> tuple[str, ...]:
        """Placement tokens in canonical order."""
        return self.table.tokens

    def sequence(self, state: int) -> tuple[str, ...]:
        """The tasks done so far in `state`, in order."""
        out = []
        while state > 0:
            out.append(self.table.tokens[self.last[state]])
            state = int(self.parent[state])
        return tuple(reversed(out))

    @cached_property
    def _sequence_index(self) -> dict[tuple[str, ...], int]:
        return {self.sequence(s): s for s in range(self.n_states)}

    def index(self, sequence: tuple[str, ...] | list[str]) -> int:
        """State id of a task sequence; UnknownStateError if the sequence is not a state."""
        seq = tuple(sequence)
        if self.n_states <= 200_000:
            found = self._sequence_index.get(seq)
            if found is not None:
                return found
            raise UnknownStateError(self.spec, seq)
        state = int(self.indices([seq])[0])
        if state < 0:
            raise UnknownStateError(self.spec, seq)
        return state

    @cached_property
    def _child_keys(self) -> np.ndarray:
        # parent * n_tokens + last of states 1..n-1. Strictly increasing, because ids are
        # canonical (by depth, then by parent, then by task in token order) and a parent's id
        # is below its children's: one binary search finds the child of a (state, task) pair.
        return self.parent[1:] * len(self.tokens) + self.last[1:]

    def successors(self, states: np.ndarray, tasks: np.ndarray) -> np.ndarray:
        """The state each (state, task) pair leads to when the task is done as named: `tasks`
        are token indices, -1 for undo; -1 where the pair is not a feasible task (an unknown
        state, below -1, or a task the state does not offer)."""
        states = np.asarray(states, dtype=np.int64)
        tasks = np.asarray(tasks, dtype=np.int64)
        out = np.full(len(states), -1, dtype=np.int64)
        known = (states >= 0) & (states < self.n_states)
        undo = known & (tasks == -1) & (states > 0)
        out[undo] = self.parent[states[undo]]
        place = np.flatnonzero(known & (tasks >= 0) & (tasks < len(self.tokens)))
        if len(place) and len(self._child_keys):
            key = states[place] * len(self.tokens) + tasks[place]
            pos = np.minimum(np.searchsorted(self._child_keys, key), len(self._child_keys) - 1)
            found = self._child_keys[pos] == key
            out[place[found]] = pos[found] + 1
        return out

    def indices(self, sequences) -> np.ndarray:
        """State ids of many task sequences at once, -1 for one that is not a state: a binary
        search per depth, no dictionary of every sequence."""
        lengths = np.fromiter(map(len, sequences), dtype=np.int64, count=len(sequences))
        flat = self.token_codes(itertools.chain.from_iterable(sequences), int(lengths.sum()))
        flat[flat == -1] = -2  # "undo" is a task, never part of a sequence
        offsets = np.cumsum(lengths) - lengths
        ids = np.zeros(len(lengths), dtype=np.int64)
        for k in range(int(lengths.max(initial=0))):
            active = np.flatnonzero((lengths > k) & (ids >= 0))
            ids[active] = self.successors(ids[active], flat[offsets[active] + k])
        return ids

    def token_codes(self, tasks, count: int) -> np.ndarray:
        """Token indices of `count` task names (-1 for undo, -2 for anything else), mapped at
        C speed (a million policy entries take a fraction of a second)."""
        code = {t: i for i, t in enumerate(self.tokens)}
        code[UNDO] = -1
        return np.fromiter(map(code.get, tasks, itertools.repeat(-2)), dtype=np.int64, count=count)

    def token_paths(self, states: np.ndarray) -> np.ndarray:
        """The sequences of `states` as token indices, one row each, padded with -1 on the
        right (as many columns as the deepest of them): built by walking up the parents, so a
        chunk of states costs a few array operations per depth."""
        states = np.asarray(states, dtype=np.int64)
        depths = self.depth[states]
        out = np.full((len(states), int(depths.max(initial=0))), -1, dtype=np.int64)
        current = states.copy()
        for level in range(out.shape[1], 0, -1):
            rows = np.flatnonzero(depths >= level)
            out[rows, level - 1] = self.last[current[rows]]
            current[rows] = self.parent[current[rows]]
        return out

    def configuration(self, state: int) -> frozenset[str]:
        """The tokens in place in `state`, order ignored."""
        m = int(self.mask[state])
        return frozenset(t for i, t in enumerate(self.table.tokens) if m >> i & 1)

    def state_kind(self, state: int) -> StateKind:
        """The kind of `state`."""
        return StateKind(int(self.kind[state]))

    def name(self, state: int) -> str:
        """The state's label from the spec's `state_names`, else its 1-based id."""
        return self.spec.state_names.get(" ".join(self.sequence(state)), str(state + 1))

    def tasks(self, state: int) -> list[tuple[str, int]]:
        """Feasible tasks from `state` as (task, next state): placements, then undo.

        Every state but the start may undo its last task (a terminal one too: the graph has a
        reverse for every edge; the MDP ends episodes there). Wrong and dead-end states offer
        only undo.
        """
        lo = int(self.first_child[state])
        out = [(self.table.tokens[self.last[c]], c) for c in range(lo, lo + self.n_children[state])]
        if state > 0:
            out.append((UNDO, int(self.parent[state])))
        return out

    def action_label(self, task: str) -> str:
        """The paper's name of a task: 'ass' + part symbol, or 'disass'."""
        if task == UNDO:
            return "disass"
        return "ass" + self.spec.parts[self.table.part[self.tokens.index(task)]].symbol

    def configurations(self) -> list[frozenset[str]]:
        """Distinct configurations, in order of first appearance."""
        _, first = np.unique(self.mask, return_index=True)
        return [self.configuration(int(s)) for s in sorted(first)]

    def to_networkx(self) -> nx.DiGraph:
        """The state graph: node = task sequence, with kind, configuration, name, depth; edges
        carry the task, the paper's action label and whether it is an undo."""
        graph = nx.DiGraph(assembly=self.spec.name)
        for s in range(self.n_states):
            graph.add_node(
                self.sequence(s),
                id=s,
                kind=self.state_kind(s).label,
                configuration=self.configuration(s),
                name=self.name(s),
                depth=int(self.depth[s]),
            )
        for s in range(self.n_states):
            for task, nxt in self.tasks(s):
                graph.add_edge(
                    self.sequence(s),
                    self.sequence(nxt),
                    task=task,
                    action=self.action_label(task),
                    undo=task == UNDO,
                )
        return graph

    def to_merged_networkx(self) -> nx.DiGraph:
        """The configuration graph: states with the same configuration merged into one node.

        An edge adds or removes one part. Right when only what is in place matters (what the
        SlotMonitor sees); the sequence graph is right when the order matters (undo = last task).
        """
        graph = nx.DiGraph(assembly=self.spec.name)
        for s in range(self.n_states):
            config = self.configuration(s)
            if config not in graph:
                graph.add_node(config, kind=self.state_kind(s).label, names=[])
            graph.nodes[config]["names"].append(self.name(s))
        for s in range(1, self.n_states):
            parent, child = self.configuration(int(self.parent[s])), self.configuration(s)
            token = self.table.tokens[self.last[s]]
            graph.add_edge(parent, child, task=token, action=self.action_label(token), undo=False)
            graph.add_edge(child, parent, task=f"remove {token}", action="disass", undo=True)
        return graph


class UnknownStateError(KeyError):
    """A task sequence that is not a state of the assembly."""

    def __init__(self, spec: AssemblySpec, sequence: tuple[str, ...]):
        self.sequence = sequence
        super().__init__(
            f"{list(sequence)} is not a state of assembly {spec.name!r} ({spec.source}): "
            "check the task sequence, or pass the --assembly it belongs to"
        )

    def __str__(self) -> str:
        return str(self.args[0])


def generate_states(spec: AssemblySpec) -> StateSpace:
    """Every feasible task sequence of `spec`, level by level from the empty base."""
    table = _token_table(spec)
    parents, lasts, depths, masks = [np.array([-1])], [np.array([-1])], [np.array([0])], []
    level = np.zeros(1, dtype=np.uint64)
    masks.append(level)
    first_child_parts, n_children_parts = [], []
    offset, next_id, depth = 0, 1, 0
    while len(level):
        feasible = _feasible(spec, table, level)
        n_kids = feasible.sum(axis=1)
        starts = next_id + np.concatenate(([0], np.cumsum(n_kids)[:-1]))
        first_child_parts.append(starts)
        n_children_parts.append(n_kids)
        rows, cols = np.nonzero(feasible)
        if len(rows) == 0:
            break
        depth += 1
        parents.append(offset + rows)
        lasts.append(cols)
        depths.append(np.full(len(rows), depth))
        level = level[rows] | table.bit[cols]
        masks.append(level)
        offset = next_id
        next_id += len(rows)
    parent = np.concatenate(parents).astype(np.int64)
    mask = np.concatenate(masks)
    first_child = np.concatenate(first_child_parts).astype(np.int64)
    n_children = np.concatenate(n_children_parts).astype(np.int64)
    if n_children[0] == 0:
        raise SpecError(f"assembly spec {spec.source}: no task is feasible from the empty base")
    kind = _kinds(spec, table, mask, n_children > 0)
    _check_correct_reachable(spec, table, mask)
    if not np.any(kind == StateKind.TERMINAL):
        raise SpecError(
            f"assembly spec {spec.source}: goal: no complete configuration satisfies the goal; "
            "relax `min_gap` or fix `correct`"
        )
    space = StateSpace(
        spec=spec,
        table=table,
        parent=parent,
        last=np.concatenate(lasts).astype(np.int64),
        depth=np.concatenate(depths).astype(np.int64),
        mask=mask,
        kind=kind,
        first_child=first_child,
        n_children=n_children,
    )
    if spec.state_names:
        _check_state_names(space)
    return space


def _check_correct_reachable(spec: AssemblySpec, table: TokenTable, masks: np.ndarray) -> None:
    """SpecError naming each `goal.correct` entry that no task sequence builds."""
    if spec.goal.correct is None:
        return
    index = {t: i for i, t in enumerate(table.tokens)}
    for i, config in enumerate(spec.goal.correct):
        bits = np.uint64(sum(int(table.bit[index[t]]) for t in config))
        if not np.any(masks == bits):
            raise SpecError(
                f"assembly spec {spec.source}: goal.correct[{i}]: {sorted(config)} cannot be "
                "built by any sequence of feasible tasks (check the mounts and precedence); "
                "fix or remove the entry"
            )


def _check_state_names(space: StateSpace) -> None:
    """`state_names` must label every generated state, by sequences that are states."""
    spec = space.spec
    unknown, named = [], set()
    for key in spec.state_names:
        try:
            named.add(space.index(tuple(key.split())))
        except UnknownStateError:
            unknown.append(key)
    if unknown:
        raise SpecError(
            f"assembly spec {spec.source}: state_names: {', '.join(map(repr, unknown))} "
            f"{'is' if len(unknown) == 1 else 'are'} not a state of the assembly; fix or "
            "remove the label(s)"
        )
    if len(named) != space.n_states:
        raise SpecError(
            f"assembly spec {spec.source}: state_names: labels {len(named)} of the "
            f"{space.n_states} generated states; label every state or remove `state_names` "
            "(unlabelled states are numbered 1, 2, ... and would clash with the labels)"
        )
    labels = list(spec.state_names.values())
    repeated = sorted({x for x in labels if labels.count(x) > 1})
    if repeated:
        raise SpecError(
            f"assembly spec {spec.source}: state_names: label(s) {repeated} given to more than "
            "one state; each state needs its own label"
        )
