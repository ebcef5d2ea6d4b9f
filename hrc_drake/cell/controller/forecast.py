"""The controller's forecast of the operator's body (`OperatorForecast`) and what a forecast
starts from (`Anchor`): the person model (`hrc_drake.cell.person`) on the desk's activity
(`hrc_drake.hri.activity`), from the task indicated (or the one predicted, with the interface's
median delay) and what the body tracker reports. A forecast is the body as spheres sampled in
time (`motion.clearance.Occupancy`), the form the separation monitor measures."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.cell.person import ARM_SPHERES, BODY_GROUPS, BODY_RADII, body_samples
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.hri.activity import Desk, HandTimeline, Person, Stay, desk_stays, stays_timeline
from hrc_drake.motion.clearance import Occupancy

# Timelines an `OperatorForecast` keeps: the few anchors of a task, each at its offsets.
TIMELINES_KEPT = 64


@dataclass(frozen=True)
class Anchor:
    """What a forecast starts from: the task the operator indicates (or is predicted to), when,
    and how far the person's timeline runs behind the model's (`lag` [s]); once the tracker
    saw the hand at a stay of the activity, `done` stays are behind it and it goes on from
    `start` (the hand seen) at `at`."""

    task: str
    at: float
    lag: float = 0.0
    done: int = 0
    start: tuple[float, float, float] | None = None


class OperatorForecast:
    """The controller's forecast of the operator's body (see the module docstring).

    `person`: the parameters assumed of the operator; `delay`, `sigma`: the interface's median
    delay from a prompt to the indication [s] and the standard deviation of its log; `spread`:
    the fraction of the timing spread below kept (`safety.forecast_spread`; 0: one timeline,
    the model's own).

    A forecast is the union of the body on a few timelines — swept volumes in time windows:
    before the indication, one per quantile of the delay (`QUANTILES`), each also `JITTER` late;
    after it, the person from `EARLY` ahead of the model to `LATE` behind it (a slower hand, a
    longer lag). The arm is timed to keep clear of them all.
    """

    SAMPLE = 0.1  # s between forecast samples
    SEARCH = 5.0  # s either side of now searched to re-anchor on the observed hand
    QUANTILES = (-1.28, -0.52, 0.0, 0.52, 1.28)  # standard normal: 10, 30, 50, 70, 90 %
    JITTER = 0.4  # s
    EARLY, LATE = 0.1, 0.3  # s ahead of and behind the model after the indication
    SEEN_LATE = 0.3  # s behind the model once the tracker saw where the activity is

    def __init__(
        self, person: Person, desk: Desk, delay: float, sigma: float = 0.0, spread: float = 1.0
    ):
        self.person, self.desk, self.delay, self.sigma = person, desk, delay, sigma
        self.spread = spread
        # The stays and timelines asked for, kept: the Supervisor compares the tracked hand
        # with the same timelines every check while the anchor stays (all are immutable).
        self._stays: dict[str, tuple[Stay, ...]] = {}
        self._timelines: dict[tuple[Anchor, float], HandTimeline] = {}

    def offsets(self, indicated: bool | str) -> tuple[float, ...]:
        """The time offsets of the timelines a forecast joins (see the class docstring):
        before the indication (False), after it (True), or once seen at a stay ("seen"); the
        same offsets once each (with `spread` 0, only 0)."""
        k = self.spread
        if indicated == "seen":
            offsets = np.linspace(0.0, k * self.SEEN_LATE, 3)
        elif indicated:
            offsets = np.linspace(-k * self.EARLY, k * self.LATE, 6)
        else:
            quantiles = [self.delay * (np.exp(k * self.sigma * z) - 1.0) for z in self.QUANTILES]
            offsets = [q + d for q in quantiles for d in (0.0, k * self.JITTER)]
        return tuple(dict.fromkeys(float(d) for d in offsets))

    def fitted(self, body) -> OperatorForecast:
        """This forecast for the person a tracked `body` (BodySpheres) at rest shows: the hand
        they work with (the side of the arm's shoulder) and where it rests."""
        if len(body.groups) < 4:
            return self
        shoulder = body.centres[body.groups[2][0]]
        torso = body.centres[body.groups[3][0]]
        left = bool(shoulder[1] < torso[1])
        rest = tuple(float(x) for x in body.centres[body.groups[0][0]])
        person = replace(self.person, left_handed=left, rest_hand=rest)
        return OperatorForecast(person, self.desk, self.delay, self.sigma, self.spread)

    def stays(self, task: str) -> tuple[Stay, ...]:
        """The stays of the activity the forecast expects after the indication of `task`."""
        found = self._stays.get(task)
        if found is None:
            found = self._stays[task] = desk_stays(self.person, self.desk, task)
        return found

    def timeline(self, anchor: Anchor, shift: float = 0.0) -> HandTimeline:
        """The hand's forecast moves for `anchor`, `shift` seconds later."""
        key = (anchor, shift)
        found = self._timelines.get(key)
        if found is None:
            if len(self._timelines) >= TIMELINES_KEPT:
                self._timelines.pop(next(iter(self._timelines)))  # the oldest
            stays = self.stays(anchor.task)[anchor.done :]
            start = anchor.at + anchor.lag + shift
            found = self._timelines[key] = stays_timeline(self.person, stays, start, anchor.start)
        return found

    def occupancy(
        self, anchor: Anchor, start: float, end: float, offsets: tuple[float, ...] = (0.0,)
    ) -> Occupancy:
        """The forecast body over [start, end]: the union of the bodies on the timelines of
        `anchor` moved by each of `offsets` [s]."""
        times = np.arange(start, end + self.SAMPLE / 2, self.SAMPLE)
        bodies = [
            body_samples(self.person, self.timeline(anchor, d), times)
            for d in dict.fromkeys(offsets)
        ]
        # Past the first timeline, the arm only: torso and head barely move between them.
        arm = ARM_SPHERES
        bodies[1:] = [
            Occupancy(b.times, b.centres[:, :arm], b.radii[:arm], b.velocities[:, :arm])
            for b in bodies[1:]
        ]
        return Occupancy(
            times,
            np.concatenate([b.centres for b in bodies], axis=1),
            np.concatenate([b.radii for b in bodies]),
            np.concatenate([b.velocities for b in bodies], axis=1),
        )

    def departure(
        self, anchor: Anchor, hand: np.ndarray, now: float, offsets: tuple[float, ...] = (0.0,)
    ) -> float:
        """How far the observed `hand` is from the nearest forecast one at `now` [m] (of the
        timelines of `anchor` moved by each of `offsets`)."""
        return min(float(np.linalg.norm(self.timeline(anchor, d).at(now) - hand)) for d in offsets)

    def reanchored(self, anchor: Anchor, hand: np.ndarray, now: float) -> tuple[Anchor, float]:
        """(the anchor whose timeline best explains the observed `hand` at `now`, moved in time
        within ±SEARCH, and the distance left)."""
        timeline = self.timeline(anchor)
        offsets = np.arange(-self.SEARCH, self.SEARCH + 1e-9, 0.05)
        gaps = np.array([np.linalg.norm(timeline.at(now + d) - hand) for d in offsets])
        # Of equally good explanations (the hand at rest fits many), the least shift.
        best = int(np.argmin(gaps + 0.01 * np.abs(offsets)))
        return replace(anchor, lag=anchor.lag - float(offsets[best])), float(gaps[best])


def distinct_spheres(
    centres: np.ndarray, radii: np.ndarray, velocities: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The spheres of one forecast sample (`Occupancy` at one time) with each repeated one
    (the same centre, radius and velocity) kept once, in their order. The timelines of a
    forecast put the hand in the same place wherever it rests on all of them: on full
    `shared-desk` its samples held 141 spheres on average, 51 of them distinct. The monitor
    takes the least scale over the (shape, sphere) pairs, one pair at a time, so a repeated
    sphere cannot change it; it only costs the monitor's time, which grows with the spheres."""
    rows = np.ascontiguousarray(np.column_stack([centres, radii, velocities]), dtype=float)
    keys = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel()
    first = np.sort(np.unique(keys, return_index=True)[1])
    if len(first) == len(radii):
        return centres, radii, velocities
    return centres[first], radii[first], velocities[first]


def forecast_body(centres: np.ndarray, radii: np.ndarray, velocities: np.ndarray) -> BodySpheres:
    """One forecast sample (`Occupancy` at one time) as the separation monitor reads a tracked
    body: each repeated sphere once (`distinct_spheres`) and, where the sample begins with a
    whole body (`OperatorForecast.occupancy`'s first timeline, which `distinct_spheres` keeps
    in place), that body's parts, so that the monitor permits no approach to the head
    (`hrc_drake.cell.contact_limits.touchable`) against the forecast as against the tracked body."""
    centres, radii, velocities = distinct_spheres(centres, radii, velocities)
    whole = len(BODY_RADII)
    begins_whole = len(radii) >= whole and np.array_equal(radii[:whole], BODY_RADII)
    return BodySpheres(centres, radii, velocities, BODY_GROUPS if begins_whole else ())


__all__ = ["Anchor", "OperatorForecast", "distinct_spheres", "forecast_body"]
