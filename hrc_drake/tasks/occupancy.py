"""Which parts may be in place when a task places or undoes a part: the occupancy the cell's
check of a layout needs (`hrc_drake.motion.occupancy`), from the spec alone.

`in_place_with(spec)` answers from the spec's placement rules, pair by pair, without generating
a state: token `t` may have token `p` in place beside it when
- `p` and `t` use neither the same base slot nor the same seat on a host;
- both may be in place at once by the counts: two tokens of one mount need its count to be 2
  or more, two of one part type its count;
- each that sits on a host has a host token under it that may be in place with the other
  token and with the other's host (`t`'s host may be `p`; `p`'s is in place before `t` is
  placed, so it is not `t`);
- no `precedence.before` rule (taken transitively) places every part of `t`'s type before any
  of `p`'s, or of `p`'s host's: then `t` is never placed, nor undone, while `p` is in place;
- when `t`'s host completes its sub-assembly first (`precedence.complete_first`), `p` is that
  host, sits on it, or may be placed before it.
A task that places `t` and the undo of `t` see the same parts in place (undo takes off the part
placed last), so one relation serves both.

The rules are pairwise, so the answer may hold pairs that no sequence reaches (where the other
parts leave no room for both, say), never fewer than `in_place_with_space`, which reads them
off a generated state space (tests/test_occupancy.py compares the two): the check it feeds may
ask for room that no run needs, never the other way round. It runs before every simulation,
where the state space (10^6 states, at scale) is not at hand.
"""

from __future__ import annotations

import numpy as np

from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.graph import StateSpace, token_table


def in_place_with(spec: AssemblySpec) -> dict[str, frozenset[str]]:
    """Placement token -> the tokens that may be in place when it is placed or undone (its host
    among them, for a token on a host); see the module docstring."""
    table = token_table(spec)
    n = len(table.tokens)
    symbols = [p.symbol for p in spec.parts]
    first = _before_closure(spec)

    def together(i: int, j: int) -> bool:
        if i == j or int(table.conflict[i]) & int(table.bit[j]):
            return False
        if table.mount[i] == table.mount[j] and table.mount_count[table.mount[i]] < 2:
            return False
        return not (table.part[i] == table.part[j] and table.part_count[table.part[i]] < 2)

    def hosts(i: int) -> list[int | None]:
        """The host tokens token i may sit on ([None]: it sits on the base)."""
        need = int(table.requires[i])
        return [h for h in range(n) if need >> h & 1] if need else [None]

    def sym(i: int | None) -> str | None:
        return None if i is None else symbols[table.part[i]]

    def after(a: int | None, b: int | None) -> bool:
        """Whether every part of b's type goes on after every one of a's (`before`)."""
        return a is not None and b is not None and (sym(a), sym(b)) in first

    def sits(t: int, p: int) -> bool:
        """Whether t and p have hosts that may all be in place together, p's before t is
        placed (so not t itself, nor of a type placed after t's), t's may be p; and, when t's
        host completes its sub-assembly first, p is that host, on it, or may come before it."""
        return any(
            (ht is None or ht == p or together(ht, p))
            and (hp is None or (hp != t and together(hp, t) and not after(t, hp)))
            and (ht is None or hp is None or ht == hp or together(ht, hp))
            and (
                ht is None
                or sym(ht) not in spec.complete_first
                or p == ht
                or hp == ht
                or not (after(ht, p) or after(ht, hp))
            )
            for ht in hosts(t)
            for hp in hosts(p)
        )

    out = {}
    for t in range(n):
        out[table.tokens[t]] = frozenset(
            table.tokens[p] for p in range(n) if together(p, t) and sits(t, p) and not after(t, p)
        )
    return out


def _before_closure(spec: AssemblySpec) -> set[tuple[str, str]]:
    """Pairs (A, B) with every A placed before any B, by `precedence.before` taken
    transitively."""
    pairs = set(spec.before)
    while True:
        more = {(a, d) for a, b in pairs for c, d in pairs if b == c} - pairs
        if not more:
            return pairs
        pairs |= more


def in_place_with_space(space: StateSpace) -> dict[str, frozenset[str]]:
    """Placement token -> the tokens in place under it in some state of `space` (the exact
    relation `in_place_with` over-approximates): for every state, its last task and the
    tokens of its parent's configuration."""
    tokens = space.tokens
    states = np.flatnonzero(space.last >= 0)
    last = space.last[states]
    before = space.mask[space.parent[states]]
    union = np.zeros(len(tokens), dtype=np.uint64)
    np.bitwise_or.at(union, last, before)
    return {
        t: frozenset(tokens[p] for p in range(len(tokens)) if int(union[i]) >> p & 1)
        for i, t in enumerate(tokens)
    }
