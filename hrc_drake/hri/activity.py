"""The operator's activity on a shared desk: where a hand goes, and when.

In the paper's cell robot and operator share one desk, and "both robot and human worker can
access all necessary components for assembly, such as base, flanges, bolts and nuts". For each
task the robot does, the operator here

1. indicates the target: the hand goes over the target seat and points (`point_time`);
2. after `fetch_lag` seconds back at rest, fetches the task part's bolts and then its nuts from
   the desk's bins (`grab_time` per handful of `handful`), and comes back to rest;
3. bolts the part the robot holds (`bolting_hand`), and withdraws before the bolts are done.

One model serves both sides of the cell: the simulated station moves the operator's body by it
(with this person's parameters, `Person`), and the controller forecasts the body by it (with the
parameters it assumes of the population, and the task it predicts). Times are absolute seconds.
Hands move from rest to rest on a minimum-jerk profile, whose peak speed is 1.875 × distance /
duration: a move takes the time that makes its peak the person's `hand_speed`.

Drake-free: the task layer and the scenario checks use it too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from hrc_drake.tasks.tokens import UNDO

BIN_HOLDS = ("bolts", "nuts")
MIN_JERK_PEAK = 1.875  # peak speed of a minimum-jerk move over its mean speed
SHORTEST_MOVE = 0.25  # s: a hand move takes at least this long, however short
POINT_ABOVE = 0.15  # m: the pointing hand's centre above the target seat
POINT_BACK = 0.22  # m: ... and this far back toward the operator (+x, across the table)
GRAB_ABOVE = 0.05  # m: the hand's centre above the bin's floor while it grabs
# The shoulder of the arm the person works with, from the stance point at table height [m]
# (the right one; a left-handed person's is mirrored in y).
SHOULDER = np.array([-0.05, 0.18, 0.50])
# How far the torso may lean toward the table to extend the reach [m] (our assumption for a
# person standing at the table edge).
LEAN = 0.25


def min_jerk(x: float) -> float:
    """The minimum-jerk profile 10x³ − 15x⁴ + 6x⁵ on [0, 1] (peak slope 1.875)."""
    x = float(np.clip(x, 0.0, 1.0))
    return x**3 * (10 - 15 * x + 6 * x**2)


def min_jerk_rate(x: float) -> float:
    """d/dx of `min_jerk` on [0, 1] (0 outside)."""
    if not 0.0 < x < 1.0:
        return 0.0
    return 30 * x**2 * (1 - x) ** 2


@dataclass(frozen=True)
class Person:
    """One operator's body and habits (positions in world [m], times [s]).

    Attributes:
        stance: [x, y] of the torso axis.
        rest_hand: where the working hand waits.
        hand_speed: the hand's peak speed [m/s].
        reach: shoulder to hand centre with the arm stretched [m].
        left_handed: works with the left hand (shoulder mirrored).
        fetch_lag: seconds at rest between pointing and fetching.
        grab_time: seconds in a bin per handful.
        handful: bolts (or nuts) taken per grab.
        point_time: seconds the hand points over the target seat.
        reach_offset: the hand from the held part while bolting.
        reach_time: seconds of the bolting reach and of its withdrawal.
    """

    stance: tuple[float, float] = (0.90, -0.05)
    rest_hand: tuple[float, float, float] = (0.70, 0.10, 0.06)
    hand_speed: float = 1.6
    reach: float = 0.62
    left_handed: bool = False
    fetch_lag: float = 0.0
    grab_time: float = 1.0
    handful: int = 4
    point_time: float = 1.0
    reach_offset: tuple[float, float, float] = (0.14, 0.0, 0.04)
    reach_time: float = 0.6

    @property
    def shoulder(self) -> np.ndarray:
        """The working arm's shoulder in world [m] (standing upright)."""
        side = -1.0 if self.left_handed else 1.0
        return np.array([self.stance[0], self.stance[1], 0.0]) + SHOULDER * [1.0, side, 1.0]

    def reaches(self, point) -> bool:
        """Whether the hand reaches `point`, leaning at most `LEAN` toward it."""
        d = np.asarray(point, dtype=float) - self.shoulder
        horizontal = max(float(np.hypot(d[0], d[1])) - LEAN, 0.0)
        return math.hypot(horizontal, float(d[2])) <= self.reach + 1e-9

    def move_time(self, a, b) -> float:
        """Seconds a hand move from `a` to `b` takes at this person's peak speed."""
        distance = float(np.linalg.norm(np.asarray(b, float) - np.asarray(a, float)))
        return max(SHORTEST_MOVE, MIN_JERK_PEAK * distance / self.hand_speed)


@dataclass(frozen=True)
class DeskBin:
    """A bin on the desk: what it `holds` (`bolts` or `nuts`) and where the hand grabs."""

    name: str
    holds: str
    grab: tuple[float, float, float]


@dataclass(frozen=True)
class Desk:
    """What the operator's activity needs of the cell: the bins, where each task's part goes
    (`seats`: task token → the seat's centre in world [m]), the part kind each task moves
    (`parts`) and how many bolts a part of each kind takes (`bolts`)."""

    bins: tuple[DeskBin, ...]
    seats: Mapping[str, tuple[float, float, float]]
    parts: Mapping[str, str] = field(default_factory=dict)
    bolts: Mapping[str, int] = field(default_factory=dict)

    def point(self, task: str) -> np.ndarray | None:
        """Where the hand points for `task` (None: no seat to point at, e.g. undo)."""
        seat = self.seats.get(task)
        if seat is None:
            return None
        return np.asarray(seat, dtype=float) + np.array([POINT_BACK, 0.0, POINT_ABOVE])

    def fetches(self, task: str, handful: int) -> list[tuple[np.ndarray, int]]:
        """(where the hand grabs, how many grabs) for the bins a task's part needs: its bolts,
        then its nuts (none for undo, or with no bins)."""
        if task == UNDO or task not in self.parts:
            return []
        count = self.bolts.get(self.parts[task], 0)
        grabs = math.ceil(count / max(handful, 1))
        out = []
        for holds in BIN_HOLDS:
            bins = [b for b in self.bins if b.holds == holds]
            if bins and grabs:
                out.append((np.asarray(bins[0].grab, dtype=float), grabs))
        return out


@dataclass(frozen=True)
class HandMove:
    """The hand from `a` at `start` to `b` at `end` (minimum jerk; a == b: it stays)."""

    start: float
    end: float
    a: np.ndarray
    b: np.ndarray
    what: str

    def at(self, t: float) -> np.ndarray:
        """The hand's position at `t` within the move."""
        x = (t - self.start) / max(self.end - self.start, 1e-9)
        return self.a + min_jerk(x) * (self.b - self.a)

    def velocity(self, t: float) -> np.ndarray:
        """The hand's velocity at `t` within the move [m/s]."""
        length = max(self.end - self.start, 1e-9)
        return min_jerk_rate((t - self.start) / length) / length * (self.b - self.a)


@dataclass(frozen=True)
class HandTimeline:
    """A hand's moves in time order; before the first and after the last the hand rests."""

    rest: np.ndarray
    moves: tuple[HandMove, ...] = ()

    @property
    def end(self) -> float:
        """When the last move ends (-inf: no moves)."""
        return self.moves[-1].end if self.moves else -math.inf

    def _move(self, t: float) -> HandMove | None:
        for move in self.moves:
            if move.start <= t <= move.end:
                return move
        return None

    def at(self, t: float) -> np.ndarray:
        """The hand's position at `t`."""
        move = self._move(t)
        return self.rest if move is None else move.at(t)

    def velocity(self, t: float) -> np.ndarray:
        """The hand's velocity at `t` [m/s]."""
        move = self._move(t)
        return np.zeros(3) if move is None else move.velocity(t)

    def doing(self, t: float) -> str:
        """What the hand does at `t` (`rest` outside every move)."""
        move = self._move(t)
        return "rest" if move is None else move.what


@dataclass(frozen=True)
class Stay:
    """Where the hand stays in an activity, for how long, doing `what`."""

    what: str
    where: np.ndarray
    dwell: float


def desk_stays(person: Person, desk: Desk, task: str) -> tuple[Stay, ...]:
    """The hand's stays after the indication of `task`: point, rest for the fetch lag, each bin
    the part needs, rest (none for a task with no seat to point at and nothing to fetch)."""
    rest = np.asarray(person.rest_hand, dtype=float)
    stays: list[Stay] = []
    point = desk.point(task)
    if point is not None:
        stays += [Stay("point", point, person.point_time), Stay("rest", rest, person.fetch_lag)]
    fetches = desk.fetches(task, person.handful)
    stays += [Stay("fetch", grab, person.grab_time * grabs) for grab, grabs in fetches]
    if fetches:
        stays.append(Stay("rest", rest, 0.0))
    return tuple(stays)


def stays_timeline(
    person: Person, stays: tuple[Stay, ...], start: float, here: np.ndarray | None = None
) -> HandTimeline:
    """The hand going from `here` (None: rest) at `start` through `stays` in turn."""
    rest = np.asarray(person.rest_hand, dtype=float)
    here = rest if here is None else np.asarray(here, dtype=float)
    moves: list[HandMove] = []
    t = start
    for stay in stays:
        arrive = t + person.move_time(here, stay.where)
        moves.append(HandMove(t, arrive, here, stay.where, stay.what))
        moves.append(HandMove(arrive, arrive + stay.dwell, stay.where, stay.where, stay.what))
        t, here = arrive + stay.dwell, stay.where
    return HandTimeline(rest, tuple(moves))


def indication_timeline(person: Person, desk: Desk, task: str, indicated_at: float):
    """The hand's moves from the indication of `task` at `indicated_at`: point, rest for the
    person's fetch lag, fetch the bolts and nuts, and rest (see the module docstring)."""
    return stays_timeline(person, desk_stays(person, desk, task), indicated_at)


def bolting_hand(person: Person, now: float, start: float, length: float, part) -> np.ndarray:
    """The hand while bolting the held part at `part` from `start` for `length` seconds: it
    reaches to the part (`reach_offset` from it) and is back at rest before the bolts are done.
    Reach and withdrawal take `reach_time` each, shortened to fit three of them in the bolting
    time; a reach the hand cannot make at its peak speed in that time stops short along the way
    (lean runs' 0.5 s holds)."""
    rest = np.asarray(person.rest_hand, dtype=float)
    phase = now - start
    if length <= 0 or not 0.0 <= phase <= length:
        return rest
    move = min(person.reach_time, length / 3)
    path = np.asarray(part, dtype=float) + person.reach_offset - rest
    reach = min(1.0, person.hand_speed * move / MIN_JERK_PEAK / max(np.linalg.norm(path), 1e-9))
    out = min_jerk(phase / move) - min_jerk((phase - (length - 1.25 * move)) / move)
    return rest + reach * out * path


def vary_person(person: Person, seed: int, spread: float) -> Person:
    """A person drawn around `person` for operator `seed`: hand speed, grab and point times
    scaled by up to ±`spread`, a fetch lag up to 4·`spread` seconds longer, and left-handed with
    probability `spread` / 2 (our assumptions: no published spread for this task). `spread` 0
    returns `person`."""
    if spread <= 0:
        return person
    rng = np.random.default_rng([seed, 19])
    scale = rng.uniform(1 - spread, 1 + spread, size=3)
    switched = bool(rng.random() < spread / 2)
    rest = person.rest_hand
    if switched:  # the other hand waits mirrored about the stance
        rest = (rest[0], 2 * person.stance[1] - rest[1], rest[2])
    return Person(
        stance=person.stance,
        rest_hand=rest,
        hand_speed=person.hand_speed * float(scale[0]),
        reach=person.reach,
        left_handed=switched != person.left_handed,
        fetch_lag=person.fetch_lag + float(rng.uniform(0.0, 4 * spread)),
        grab_time=person.grab_time * float(scale[1]),
        handful=person.handful,
        point_time=person.point_time * float(scale[2]),
        reach_offset=person.reach_offset,
        reach_time=person.reach_time,
    )


__all__ = [
    "BIN_HOLDS",
    "Desk",
    "DeskBin",
    "HandMove",
    "HandTimeline",
    "Person",
    "Stay",
    "bolting_hand",
    "desk_stays",
    "indication_timeline",
    "min_jerk",
    "stays_timeline",
    "vary_person",
]
