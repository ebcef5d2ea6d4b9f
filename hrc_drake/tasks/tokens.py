"""Task tokens: the names of placements, shared by the task layer, the motion layer and the cell.

A token is a part symbol followed by where the part goes:
- on the base: the base slots it covers, e.g. ``F1``, ``S12``;
- on a host part: the host's tag and the base slot it sits over, e.g. ``F01`` (tag ``0``).
Slot numbers are written as digits when the base has at most nine slots, else joined by ``-``
(``F10``, ``S9-10``) so that tokens stay unambiguous. ``undo`` removes the last part placed.

Tokens are written here and read in one place only: `AssemblySpec.placement(token)`.
"""

from __future__ import annotations

from dataclasses import dataclass

UNDO = "undo"


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
