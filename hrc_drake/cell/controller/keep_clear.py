"""Predictive separation: the Supervisor times its plan around where it forecasts the operator.

With `safety.separation: predictive` and an operator who shares the desk, the Supervisor keeps an
`OperatorForecast` (`hrc_drake.cell.station.desk`): from the task the operator indicated (before the
indication: the task the robot committed to, at the interface's median delay) it forecasts the
body over the plan's horizon, and asks the motion layer (`hrc_drake.motion.clearance`) where the
arm should wait so that speed-and-separation monitoring is forecast never to slow it. It times
the plan again

- when the plan, the indicated task or the bolts change (each task boundary: the forecast is
  solved again there);
- when the tracked hand reaches a stay of the activity (the pointing pose, a bin) or leaves the
  one it was at: the forecast goes on from there, with a narrower timing spread (the person's
  progress, seen);
- when the tracked body departs from every forecast timeline by more than `safety.departure`:
  the forecast is moved in time to the moment of the person's timeline that explains the
  observed hand (a person running late or early), and if none does, the observed body is taken
  to stay where it is for `STAY` seconds (counted in `replans`).

Once the tracker shows the hand in the last bin of its fetch, from where it only goes back to
rest, away from the robot, each wait is the cheapest one: the arm may go on slowed beside the
hand instead of waiting until it has left.

Before the first task it fits the forecast to the person the tracker shows at rest: the hand
they work with and where it rests.

The separation monitor stays underneath and acts on the body as measured; the waits only keep
it from having to.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue

from hrc_drake.cell.controller.forecast import Anchor, OperatorForecast
from hrc_drake.cell.controller.supervisor_state import Mode, SupervisorStatus
from hrc_drake.cell.person import ARM_SPHERES
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.motion.clearance import Occupancy, ScaleFn, time_around
from hrc_drake.tasks.tokens import UNDO

CHECK_PERIOD = 0.1  # s between comparisons of the tracked body with the forecast
RETIME_PERIOD = 1.0  # s: a departure re-times the plan at most this often
STAY = 1.0  # s an unexplained body is forecast to stay where it is seen
STILL = 0.02  # m/s: a hand this slow is at rest
VISIT, LEAVE = 0.06, 0.10  # m: the hand is at a stay within VISIT of it, and left past LEAVE
VIEW_TIMES = np.arange(0.0, 3.01, 0.25)  # s ahead at which the forecast hand is drawn

_NOBODY = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))


@dataclass(frozen=True)
class KeepClearSettings:
    """What predictive separation needs: the operator's forecast and the speed scale the
    monitor would allow (`ScaleFn`); both None: reactive (monitoring alone). `max_wait` and
    `departure` are `SafetyConfig`'s."""

    forecast: OperatorForecast | None = None
    scale: ScaleFn | None = None
    max_wait: float = 6.0
    departure: float = 0.15


class KeepClear:
    """The Supervisor's predictive separation (see the module docstring); a mixin of
    `hrc_drake.cell.controller.supervisor.Supervisor`."""

    def _declare_keep_clear(self, settings: KeepClearSettings) -> None:
        self._forecast, self._scale = settings.forecast, settings.scale
        # Fitted to the person once seen at rest: the controller's model of who stands there,
        # learned once per run (a Supervisor runs one simulation).
        self._fitted: OperatorForecast | None = None
        self._max_wait, self._departure = settings.max_wait, settings.departure
        self._body_port = self.DeclareAbstractInputPort(
            "operator.body", AbstractValue.Make(_NOBODY)
        )

    def _anchor(self, s: SupervisorStatus) -> Anchor | None:
        """The indication the forecast starts from: the operator's, or the one predicted."""
        if s.pending is None:
            return None
        if s.seen is not None:
            return s.seen
        if s.indicated_at is not None:
            return Anchor(s.pending[1], s.indicated_at)
        task = s.committed or s.pending[1]
        return Anchor(task, s.asked_at + self._forecast.delay)

    def _offsets(self, s: SupervisorStatus) -> tuple[float, ...]:
        """The forecast's timing spread: narrower once the tracker showed where it is."""
        if s.seen is not None and (s.seen.done > 0 or s.visiting is not None):
            return self._forecast.offsets("seen")
        return self._forecast.offsets(s.indicated_at is not None)

    def _progress(self, s: SupervisorStatus, hand: np.ndarray, now: float):
        """(the anchor, the stay visited) when the tracked hand reached a stay of the activity
        (pointing, a bin) or left the one it was at; None otherwise."""
        if s.indicated_at is None:
            return None
        task = s.pending[1]
        stays = self._forecast.stays(task)
        here = tuple(float(x) for x in hand)
        if s.visiting is not None:
            if np.linalg.norm(hand - stays[s.visiting].where) > LEAVE:
                return Anchor(task, now, done=s.visiting + 1, start=here), None
            return None
        first = s.seen.done if s.seen is not None else 0
        for k in range(first, len(stays)):
            if stays[k].what != "rest" and np.linalg.norm(hand - stays[k].where) < VISIT:
                return Anchor(task, now, done=k, start=here), k
        return None

    def _at_last_bin(self, s: SupervisorStatus) -> bool:
        """Whether the tracker shows the hand in the last bin of its fetch: from there it only
        goes back to rest, away from the robot."""
        if s.visiting is None or s.pending is None:
            return False
        stays = self._forecast.stays(s.pending[1])
        fetches = [k for k, stay in enumerate(stays) if stay.what == "fetch"]
        return bool(fetches) and s.visiting == fetches[-1]

    def _fit(self, body: BodySpheres) -> None:
        """Fit the forecast to the person the tracker shows at rest before the first task (the
        controller knows the population's operator, not which hand this one works with or
        where it rests)."""
        if len(body.radii) and np.linalg.norm(body.velocities[0]) < STILL:
            self._forecast = self._forecast.fitted(body)
            self._fitted = self._forecast

    def _tracked_body(self, context) -> BodySpheres:
        if not self._body_port.HasValue(context):
            return _NOBODY
        return self._body_port.Eval(context)

    def _keep_clear(self, s: SupervisorStatus, context, now: float) -> SupervisorStatus:
        """Re-time the plan when what it was timed for changed, or the body departs from the
        forecast (see the module docstring)."""
        if self._forecast is None:
            return s
        if self._fitted is None and s.step <= 1 and s.indicated_at is None:
            self._fit(self._tracked_body(context))  # before the operator's first move
        if s.mode != Mode.EXECUTE or s.plan is None:
            return s
        key = (id(s.plan), s.step, s.pending[1], s.indicated_at, s.bolted)
        if key != s.clear_key:
            s = replace(s, seen=None, visiting=None)
            return self._retime(s, key, now, None)
        if now - s.checked_at < CHECK_PERIOD:
            return s
        body = self._tracked_body(context)
        anchor = self._anchor(s)
        if len(body.radii) == 0 or anchor is None:
            return s
        hand = body.centres[0]
        progress = self._progress(s, hand, now)
        if progress is not None:
            s = replace(s, seen=progress[0], visiting=progress[1])
            return self._retime(s, key, now, None)
        offsets = self._offsets(s)
        if self._forecast.departure(anchor, hand, now, offsets) <= self._departure:
            return replace(s, checked_at=now)
        if now - s.timed_at < RETIME_PERIOD:
            return replace(s, checked_at=now)
        moved, left = self._forecast.reanchored(anchor, hand, now)
        s = replace(s, seen=moved, replans=s.replans + 1)
        unexplained = body if left > self._departure else None
        return self._retime(s, key, now, unexplained)

    def _retime(self, s, key: tuple, now: float, unexplained: BodySpheres | None):
        """The plan's waits from the forecast at `now` (with an observed body that the forecast
        does not explain, taken to stay `STAY` seconds)."""
        anchor = self._anchor(s)
        plan, tau = s.plan, s.plan_time(now)
        # Up to the hold for the bolts (its end depends on the operator), or to the end of a
        # plan that holds for none (an undo, a part put back) or is past its hold.
        holds_for_bolts = plan.task != UNDO and not s.bolted
        end_tau = plan.t_in_place if holds_for_bolts else plan.duration
        horizon = max(end_tau - tau, 0.0) + self._max_wait + 1.0
        occupancy = self._forecast.occupancy(anchor, now, now + horizon, self._offsets(s))
        if unexplained is not None:
            occupancy = _staying(occupancy, unexplained, now + STAY)
        holds, spent = (), None
        if s.held_since is not None:
            spent = (s.held_since[0], now - s.held_since[1])
        if tau < end_tau:
            holds = time_around(
                plan,
                tau,
                now,
                occupancy,
                self._scale,
                self._max_wait,
                end_tau,
                spent=spent,
                slowing_ok=self._at_last_bin(s),
            )
        timeline = self._forecast.timeline(anchor)
        view = tuple(tuple(float(x) for x in timeline.at(now + d)) for d in VIEW_TIMES)
        return replace(
            s, holds=holds, clear_key=key, timed_at=now, checked_at=now, forecast_view=view
        )


def _staying(occupancy: Occupancy, body: BodySpheres, until: float) -> Occupancy:
    """`occupancy` with the observed `body` standing still in place of the forecast until
    `until`. The forecast's first timeline is a whole body and each further one its arm
    (`OperatorForecast.occupancy`), so each is replaced by the body's same spheres; a body of
    another sphere count than the forecast's replaces nothing."""
    n, total = len(body.radii), occupancy.centres.shape[1]
    arm = min(ARM_SPHERES, n)
    if n == 0 or total < n or (total - n) % arm:
        return occupancy
    index = np.concatenate([np.arange(n), np.tile(np.arange(arm), (total - n) // arm)])
    centres, velocities = occupancy.centres.copy(), occupancy.velocities.copy()
    now = occupancy.times <= until
    centres[now] = body.centres[index]
    velocities[now] = body.velocities[index]
    return replace(occupancy, centres=centres, velocities=velocities)


__all__ = ["KeepClear", "KeepClearSettings"]
