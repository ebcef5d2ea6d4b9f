"""Bets: how the task the robot committed to relates to the one the operator indicates (no
Drake). A right bet is the task itself; a re-target puts the same part in another seat; a swap
is another part, or an undo. The cost table prices re-targets and swaps (`hrc_drake.tasks.costs`),
the interaction model adds them to a task's time (`hrc_drake.tasks.interaction`)."""

from __future__ import annotations

from enum import StrEnum

from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO


class Bet(StrEnum):
    """How the committed task relates to the indicated one."""

    RIGHT = "right"
    RETARGET = "retarget"
    SWAP = "swap"


def bet_kind(space: StateSpace, committed: str, indicated: str) -> Bet:
    """Right, re-target (the same part to another seat) or swap (another part, or undo)."""
    if indicated == committed:
        return Bet.RIGHT
    if indicated == UNDO or committed == UNDO:
        return Bet.SWAP
    same = space.spec.placement(committed).part == space.spec.placement(indicated).part
    return Bet.RETARGET if same else Bet.SWAP


__all__ = ["Bet", "bet_kind"]
