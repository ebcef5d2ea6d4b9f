"""A person the forecast has not seen: the desk activity of `hrc_drake.hri.activity` done the
way a real person might, outside the family the controller's forecast is drawn from.

The modelled person (`desk_stays`, `stays_timeline`) points, rests `fetch_lag`, fetches bolts
then nuts and rests, every move from rest to rest at one peak speed. The unseen person does the
same job but

- keeps other timing: their own top speed (up to `HUMAN_SPEED`) and a speed drawn for each
  move below it, pointing, lag and grab times drawn per indication around other values than the
  model's (the lag sometimes much longer), and sometimes goes straight from pointing to the
  bins without coming back to rest;
- **hesitates**: a reach stops partway, the hand stands still, then goes on to the same goal;
- **changes their mind**: a reach sets off toward another place (the other bin, another seat)
  and turns to its goal on the way — a second minimum-jerk submovement, from the abandoned
  target to the new one, added to the first from the moment of the switch (Flash and Henis
  1991, "Arm trajectory modifications during reaching towards visual targets");
- **fetches again**: after the nuts, goes back to a bin for one more grab (a part dropped).

Each operator seed is one such person (`unseen_person`); each indication of theirs is drawn
from the seed, the decision step and the task, so the same seed gives the same hand. Every move
keeps a human hand's peak speed (≤ `HUMAN_SPEED`) and acceleration (≤ `HUMAN_ACCELERATION`),
and every point of it lies in the convex hull of places the person reaches (so within
`Person.reaches`). Only the simulated station moves a body by it: the controller's forecast
keeps modelling the ordinary person.

Drake-free, like `hrc_drake.hri.activity`.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from hrc_drake.hri.activity import (
    MIN_JERK_PEAK,
    SHORTEST_MOVE,
    Desk,
    HandMove,
    HandTimeline,
    Person,
    Stay,
    desk_stays,
    min_jerk,
    min_jerk_rate,
)

HUMAN_SPEED = 1.6  # m/s: the most a hand moves here (ISO 13855's walking-speed value)
# m/s²: the most a hand accelerates here, below the modelled hands' bolting reach in lean runs
# (24-29 m/s²).
HUMAN_ACCELERATION = 20.0
MIN_JERK_ACCELERATION = 10 / math.sqrt(3)  # peak acceleration × duration² / distance
STREAM = 29  # the random stream of unseen persons (vary_person draws from 19)
DECOY_APART = 0.08  # m: a place this close to the goal is not another place


@dataclass(frozen=True)
class UnseenPerson:
    """How one unseen person departs from the model (drawn by `unseen_person`).

    Attributes:
        seed: the operator seed the person was drawn for (each indication draws from it).
        speed: the person's top hand speed [m/s]; each move goes at 0.7-1 of it.
        lag: the mean fetch lag [s] (exponential: mostly short, now and then long).
        timing: the spread of the log of the point and grab times around the model's.
        hesitate: the probability a reach pauses partway.
        change_mind: the probability a reach sets off toward another place first.
        refetch: the probability of a second fetch after the nuts.
        direct: the probability of going straight from pointing to the bins.
    """

    seed: int
    speed: float
    lag: float
    timing: float
    hesitate: float
    change_mind: float
    refetch: float
    direct: float


def unseen_person(seed: int) -> UnseenPerson:
    """The unseen person of operator `seed` (our assumptions; no published spread)."""
    rng = np.random.default_rng([seed, STREAM])
    return UnseenPerson(
        seed=seed,
        speed=float(rng.uniform(0.9, HUMAN_SPEED)),
        lag=float(rng.uniform(0.3, 1.5)),
        timing=float(rng.uniform(0.2, 0.5)),
        hesitate=float(rng.uniform(0.25, 0.45)),
        change_mind=float(rng.uniform(0.2, 0.4)),
        refetch=float(rng.uniform(0.3, 0.7)),
        direct=float(rng.uniform(0.0, 0.5)),
    )


def move_time(distance: float, speed: float) -> float:
    """Seconds a minimum-jerk move of `distance` takes at most `speed` peak and at most
    `HUMAN_ACCELERATION`."""
    by_speed = MIN_JERK_PEAK * distance / speed
    by_acceleration = math.sqrt(MIN_JERK_ACCELERATION * distance / HUMAN_ACCELERATION)
    return max(SHORTEST_MOVE, by_speed, by_acceleration)


@dataclass(frozen=True)
class TurningMove(HandMove):
    """A reach that changes its mind: from `a` toward `aside` (minimum jerk over [start,
    `aside_end`]), and from `turn` on a second submovement from `aside` to the goal `b` added to
    it, ending at `end`."""

    aside: np.ndarray
    turn: float
    aside_end: float

    def _phases(self, t: float) -> tuple[float, float]:
        return (t - self.start) / (self.aside_end - self.start), (t - self.turn) / (
            self.end - self.turn
        )

    def at(self, t: float) -> np.ndarray:
        """The hand's position at `t` within the move."""
        x1, x2 = self._phases(t)
        return self.a + min_jerk(x1) * (self.aside - self.a) + min_jerk(x2) * (self.b - self.aside)

    def velocity(self, t: float) -> np.ndarray:
        """The hand's velocity at `t` within the move [m/s]."""
        x1, x2 = self._phases(t)
        first = min_jerk_rate(x1) / (self.aside_end - self.start) * (self.aside - self.a)
        return first + min_jerk_rate(x2) / (self.end - self.turn) * (self.b - self.aside)


def peaks(move: HandMove, samples: int = 200) -> tuple[float, float]:
    """(peak speed [m/s], peak acceleration [m/s²]) of `move`, sampled."""
    times = np.linspace(move.start, move.end, samples)
    velocity = np.array([move.velocity(t) for t in times])
    acceleration = np.gradient(velocity, times, axis=0)
    return (
        float(np.linalg.norm(velocity, axis=1).max()),
        float(np.linalg.norm(acceleration, axis=1).max()),
    )


def turning_move(start, here, aside, goal, speed: float, switch: float, what: str) -> TurningMove:
    """A reach from `here` that sets off toward `aside` and, `switch` (0-1) of the way through
    that move, turns to `goal`; slowed until its peaks are human."""
    first = move_time(float(np.linalg.norm(aside - here)), speed)
    second = move_time(float(np.linalg.norm(goal - aside)), speed)
    # The second submovement lasts at least the rest of the first: the hand stays between
    # here, aside and goal (the superposition's weights stay in [0, 1]).
    second = max(second, (1 - switch) * first)
    for _ in range(40):
        turn = start + switch * first
        end = max(turn + second, start + first)
        move = TurningMove(start, end, here, goal, what, aside, turn, start + first)
        speed_peak, acceleration_peak = peaks(move)
        if speed_peak <= speed and acceleration_peak <= HUMAN_ACCELERATION:
            return move
        first, second = 1.1 * first, 1.1 * second
    return move


def _decoys(person: Person, desk: Desk, task: str, here, goal) -> list[np.ndarray]:
    """Other places a reach from `here` to `goal` might set off toward: the bins, and where the
    hand points for the other seats, that the person reaches."""
    places = [np.asarray(b.grab, dtype=float) for b in desk.bins]
    places += [desk.point(t) for t in desk.seats if t != task]
    return [
        p
        for p in places
        if min(np.linalg.norm(p - goal), np.linalg.norm(p - here)) > DECOY_APART
        and person.reaches(p)
    ]


def _stays(person: Person, unseen: UnseenPerson, desk: Desk, task: str, rng) -> list[Stay]:
    """The stays of the activity after the indication of `task`, timed the unseen person's way:
    maybe straight from pointing to the bins, maybe a second fetch before the rest."""

    def timing() -> float:
        return float(rng.lognormal(0.0, unseen.timing))

    model = desk_stays(person, desk, task)
    fetching = any(s.what == "fetch" for s in model)
    stays = []
    for stay in model:
        if stay.what == "point":
            stays.append(Stay("point", stay.where, person.point_time * timing()))
        elif stay.what == "fetch":
            stays.append(Stay("fetch", stay.where, stay.dwell * timing()))
        elif stays and stays[-1].what == "point" and fetching:  # the lag before fetching
            if rng.random() >= unseen.direct:
                stays.append(Stay("rest", stay.where, float(rng.exponential(unseen.lag))))
        else:
            stays.append(stay)
    # A second fetch goes back to a bin fetched from before the last one (a part dropped).
    fetches = [s for s in stays if s.what == "fetch"]
    again = [s for s in fetches if np.linalg.norm(s.where - fetches[-1].where) > DECOY_APART]
    if again and rng.random() < unseen.refetch:
        where = again[int(rng.integers(len(again)))].where
        stays.insert(len(stays) - 1, Stay("fetch", where, person.grab_time * timing()))
    return stays


def _reach(person, unseen, desk, task, here, stay: Stay, t: float, rng) -> list[HandMove]:
    """The moves of one reach from `here` at `t` to `stay` (plain, hesitant or turning)."""
    speed = unseen.speed * float(rng.uniform(0.7, 1.0))
    goal = stay.where
    u = rng.random()
    # Only a reach to a stay (not back to rest), and one long enough to show it, is irregular.
    irregular = stay.what != "rest" and np.linalg.norm(goal - here) > DECOY_APART
    if irregular and u < unseen.change_mind:
        decoys = _decoys(person, desk, task, here, goal)
        if decoys:
            aside = decoys[int(rng.integers(len(decoys)))]
            switch = float(rng.uniform(0.3, 0.55))
            return [turning_move(t, here, aside, goal, speed, switch, stay.what)]
    if irregular and u < unseen.change_mind + unseen.hesitate:
        stop = here + float(rng.uniform(0.35, 0.65)) * (goal - here)
        pause = float(rng.uniform(0.3, 0.9))
        reach = t + move_time(float(np.linalg.norm(stop - here)), speed)
        on = reach + pause
        last = on + move_time(float(np.linalg.norm(goal - stop)), speed)
        return [
            HandMove(t, reach, here, stop, stay.what),
            HandMove(reach, on, stop, stop, "hesitate"),
            HandMove(on, last, stop, goal, stay.what),
        ]
    arrive = t + move_time(float(np.linalg.norm(goal - here)), speed)
    return [HandMove(t, arrive, here, goal, stay.what)]


def unseen_timeline(
    person: Person, unseen: UnseenPerson, desk: Desk, task: str, indicated_at: float, step: int
) -> HandTimeline:
    """The unseen person's hand after the indication of `task` at `indicated_at`, decision
    `step` (see the module docstring): the same for the same seed, step and task."""
    rng = np.random.default_rng([unseen.seed, STREAM, step, zlib.crc32(task.encode())])
    rest = np.asarray(person.rest_hand, dtype=float)
    here, t, moves = rest, indicated_at, []
    for stay in _stays(person, unseen, desk, task, rng):
        reach = _reach(person, unseen, desk, task, here, stay, t, rng)
        arrive = reach[-1].end
        moves += [*reach, HandMove(arrive, arrive + stay.dwell, stay.where, stay.where, stay.what)]
        t, here = arrive + stay.dwell, stay.where
    return HandTimeline(rest, tuple(moves))


__all__ = [
    "HUMAN_ACCELERATION",
    "HUMAN_SPEED",
    "TurningMove",
    "UnseenPerson",
    "move_time",
    "peaks",
    "turning_move",
    "unseen_person",
    "unseen_timeline",
]
