"""An assembly spec as values: part types, mounts, goal rules and `AssemblySpec`, which names
every placement token the spec allows and reads tokens back into placements.

Apart from `hrc_drake.tasks.spec`, which reads and validates the YAML file into these values:
the task graph, the cost tables and the cell use a spec without reading one.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hrc_drake.tasks.tokens import UNDO, Placement, placement_token

BASE = "base"
# Seconds the operator takes to bolt a part when its spec gives no `bolt_time`: the robot's
# bolting hold in the cell (MotionOptions.hold_time).
DEFAULT_BOLT_TIME = 5.0
# Bolts per part when the spec does not say (our assumption: the paper says its flanges are
# bolted, with bolts and nuts on the desk, but not how many).
DEFAULT_BOLTS = 4


class SpecError(ValueError):
    """An assembly spec that cannot be used; the message names the key and the fix."""


@dataclass(frozen=True)
class PartType:
    """A kind of part: its symbol, how many there are, how many slots it covers."""

    symbol: str
    name: str
    count: int
    footprint: int
    host_tag: str | None = None
    bolt_time: float | None = None
    """Seconds the operator takes to bolt one part (None: `DEFAULT_BOLT_TIME`)."""
    bolts: int = 0
    """Bolts (each with its nut) the operator fetches for one part (0: `DEFAULT_BOLTS`). Not
    part of the hash: it moves the operator's hands, not the states or rewards."""

    @property
    def bolt_count(self) -> int:
        """The bolts one part takes (`bolts`, or `DEFAULT_BOLTS`)."""
        return self.bolts or DEFAULT_BOLTS

    @property
    def is_host(self) -> bool:
        """Whether other parts can be mounted on this one."""
        return self.host_tag is not None


@dataclass(frozen=True)
class Mount:
    """`count` parts of type `part` go on `on` (the base, or a host part's symbol)."""

    part: str
    on: str
    count: int


@dataclass(frozen=True)
class GapRule:
    """Correctness rule: any two parts of types `parts` sit at least `slots` slots apart."""

    parts: tuple[str, str]
    slots: int


@dataclass(frozen=True)
class Goal:
    """Which complete configurations are correct."""

    min_gap: tuple[GapRule, ...] = ()
    correct: tuple[frozenset[str], ...] | None = None


@dataclass(frozen=True)
class AssemblySpec:
    """A validated assembly spec."""

    name: str
    base_symbol: str
    slots: int
    parts: tuple[PartType, ...]
    mounts: tuple[Mount, ...]
    complete_first: tuple[str, ...]
    before: tuple[tuple[str, str], ...]
    goal: Goal
    mistakes: tuple[tuple[str, str], ...]
    state_names: Mapping[str, str]
    source: str = "<memory>"
    cell: Mapping[str, Any] | None = None
    """The `cell:` section as parsed YAML: the physical cell's layout (read by the cell layer,
    not part of the MDP, so not in `spec_hash`)."""

    def part(self, symbol: str) -> PartType:
        """The part type with this symbol; SpecError if there is none."""
        for part in self.parts:
            if part.symbol == symbol:
                return part
        raise SpecError(f"{self.source}: unknown part {symbol!r}; parts are {self._symbols()}")

    def _symbols(self) -> list[str]:
        return [p.symbol for p in self.parts]

    @property
    def total_parts(self) -> int:
        """How many parts a complete assembly holds."""
        return sum(p.count for p in self.parts)

    def semantic_dict(self) -> dict[str, Any]:
        """The content that determines states and rewards (no labels, no file name)."""
        return {
            "base": {"symbol": self.base_symbol, "slots": self.slots},
            # bolt_time only when set, so that specs without it keep their hash (and policies).
            "parts": [
                [p.symbol, p.count, p.footprint, p.host_tag]
                + ([] if p.bolt_time is None else [p.bolt_time])
                for p in self.parts
            ],
            "mounts": [[m.part, m.on, m.count] for m in self.mounts],
            "complete_first": list(self.complete_first),
            "before": [list(pair) for pair in self.before],
            "goal": {
                "min_gap": [[list(r.parts), r.slots] for r in self.goal.min_gap],
                "correct": None
                if self.goal.correct is None
                else sorted(sorted(c) for c in self.goal.correct),
            },
            "mistakes": [list(m) for m in self.mistakes],
        }

    @property
    def spec_hash(self) -> str:
        """A hash of the semantic content: policies record it to refuse a mismatched spec."""
        text = json.dumps(self.semantic_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def placement(self, token: str) -> Placement:
        """What a task token places: part symbol, base slots under it, host symbol and tag.

        The one reading of tokens in the project; SpecError naming the valid tokens if `token`
        is not a placement of this spec (``undo`` is not a placement).
        """
        table = self._placement_table()
        if token not in table:
            raise SpecError(
                f"{self.source}: {token!r} is not a placement of assembly {self.name!r}; "
                f"placements are {', '.join(table)}"
            )
        return table[token]

    def placement_of(self, part: str, slots: tuple[int, ...], host: str | None = None) -> Placement:
        """The placement of `part` over base `slots` (on the base, or on host part `host`)."""
        for placement in self._placement_table().values():
            if (placement.part, placement.slots, placement.host) == (part, tuple(slots), host):
                return placement
        where = "the base" if host is None else host
        raise SpecError(
            f"{self.source}: no placement of {part!r} on {where} over slots {list(slots)}"
        )

    def _placement_table(self) -> dict[str, Placement]:
        cached = self.__dict__.get("_placements_cache")
        if cached is None:
            cached = {
                token: Placement(
                    part=mount.part,
                    slots=slots,
                    host=None if mount.on == BASE else mount.on,
                    host_tag=None if mount.on == BASE else self.part(mount.on).host_tag,
                )
                for token, mount, slots in self.placements()
            }
            object.__setattr__(self, "_placements_cache", cached)
        return cached

    def placements(self) -> list[tuple[str, Mount, tuple[int, ...]]]:
        """Every placement token the spec allows, in canonical order, with its mount and slots.

        Canonical order: parts in spec order, then mounts in spec order, then slots ascending.
        Ties between equally good tasks are broken in this order.
        """
        out: list[tuple[str, Mount, tuple[int, ...]]] = []
        seen: set[str] = set()
        for part in self.parts:
            for mount in self.mounts:
                if mount.part != part.symbol:
                    continue
                if mount.on == BASE:
                    windows = [
                        tuple(range(s, s + part.footprint))
                        for s in range(1, self.slots - part.footprint + 2)
                    ]
                    tag = None
                else:
                    windows = [(k,) for k in range(1, self.slots + 1)]
                    tag = self.part(mount.on).host_tag
                for slots in windows:
                    token = placement_token(part.symbol, slots, tag)
                    if token in seen or token == UNDO:
                        raise SpecError(
                            f"{self.source}: token {token!r} is produced twice; give the hosts "
                            "distinct `host.tag` values and parts distinct symbols"
                        )
                    seen.add(token)
                    out.append((token, mount, slots))
        return out
