"""Task tokens: the names of placements, shared by the task layer, the motion layer and the cell.

A token is a part symbol followed by where the part goes:
- on the base: the base slots it covers, e.g. ``F1``, ``S12``;
- on a host part: the host's tag and the base slot it sits over, e.g. ``F01`` (tag ``0``).
Slot numbers are written as digits when the base has at most nine slots, else joined by ``-``
(``F10``, ``S9-10``) so that tokens stay unambiguous. ``undo`` removes the last part placed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

UNDO = "undo"

_TOKEN = re.compile(r"^(?P<part>[A-Z][A-Za-z]*)(?P<where>[0-9\-]+)$")


@dataclass(frozen=True)
class Placement:
    """Where one part goes: its symbol, the base slots under it, and its host (None = base)."""

    part: str
    slots: tuple[int, ...]
    host: str | None = None
    host_tag: str | None = None

    @property
    def token(self) -> str:
        """The task token of this placement."""
        return placement_token(self.part, self.slots, self.host_tag)


def _slots_text(slots: tuple[int, ...]) -> str:
    if all(1 <= s <= 9 for s in slots):
        return "".join(str(s) for s in slots)
    return "-".join(str(s) for s in slots)


def placement_token(part: str, slots: tuple[int, ...], host_tag: str | None = None) -> str:
    """Token for `part` covering base `slots`, or sitting on a host with `host_tag` over them."""
    if not slots:
        raise ValueError(f"placement of part {part!r} names no slot")
    where = _slots_text(tuple(slots))
    if host_tag is None:
        return f"{part}{where}"
    if not all(1 <= s <= 9 for s in slots):
        where = "-" + where
    return f"{part}{host_tag}{where}"


def parse_base_token(token: str) -> tuple[str, tuple[int, ...]]:
    """Split a base token such as ``S12`` or ``S9-10`` into (part, slots); ValueError if not one."""
    match = _TOKEN.match(token)
    if match is None:
        raise ValueError(f"{token!r} is not a task token (expected a part symbol and slots)")
    where = match["where"]
    slots = tuple(int(s) for s in where.split("-")) if "-" in where else tuple(map(int, where))
    return match["part"], slots
