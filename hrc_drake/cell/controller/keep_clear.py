"""Predictive separation: the Supervisor times its plan around where it forecasts the operator.

With `safety.separation: predictive` and an operator who shares the desk, the Supervisor keeps
an `OperatorForecast` (`hrc_drake.cell.controller.forecast`): from the task the operator
indicated (before the indication: the task the robot committed to, at the interface's median
delay) it forecasts the body over the plan's horizon, and asks the motion layer
(`hrc_drake.motion.clearance`) where the arm should wait so that speed-and-separation
monitoring is forecast never to slow it. It times the plan again

- when the plan, the indicated task or the bolts change (each task boundary: the forecast is
  solved again there);
- when the tracked hand reaches a stay of the activity (the pointing pose, a bin) or leaves the
  one it was at: the forecast goes on from there, with a narrower timing spread (the person's
  progress, seen);
- when the tracked body departs from every forecast timeline by more than `safety.departure`:
  the forecast is moved in time to the moment of the person's timeline that explains the
  observed hand (a person running late or early), and if none does, the observed body is taken
  to stay where it is for `STAY` seconds (counted in `replans`).

With `safety.timing: path_time` it times each motion along its path instead
(`hrc_drake.motion.path_time`): a wait at the motion's start and the speed the arm keeps under
along it, which may slow it down or stop it mid-path for the forecast body and go on when the
body has left. A motion under way is timed from where the arm is, at its speed; and when the
arm has fallen more than `SLIP` seconds of plan time off its timing (the monitor slowed it for
a body unlike the forecast), the plan is timed again from there (counted in `slips`).

Once the tracker shows the hand in the last bin of its fetch, from where it only goes back to
rest, away from the robot, each wait (`wait` timing) is the cheapest one: the arm may go on
slowed beside the hand instead of waiting until it has left. With separation alone
(`safety.contact_speed: 0`) the monitor keeps S_p by itself, and a wait is taken only where it
clears the motion of the forecast body (`KeepClearSettings.clear_only`).

Before the first task it fits the forecast to the person the tracker shows at rest: the hand
they work with and where it rests.

The separation monitor stays underneath and acts on the body as measured; the waits only keep
it from having to.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.cell.controller.follower import timed
from hrc_drake.cell.controller.forecast import Anchor, OperatorForecast
from hrc_drake.cell.controller.supervisor_state import Mode, SupervisorStatus
from hrc_drake.cell.person import ARM_SPHERES
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.motion.clearance import Occupancy, ScaleFn, time_around
from hrc_drake.motion.path_time import path_time_around, slip
from hrc_drake.scenario.safety import Timing
from hrc_drake.tasks.tokens import UNDO

CHECK_PERIOD = 0.1  # s between comparisons of the tracked body with the forecast
RETIME_PERIOD = 1.0  # s: a departure re-times the plan at most this often
STAY = 1.0  # s an unexplained body is forecast to stay where it is seen
# s of plan time the arm may be off its path timing before it is timed again: the Supervisor
# follows a timing's speeds within the ramp, up to a step (0.1 s) behind it (our choice).
SLIP = 0.2
STILL = 0.02  # m/s: a hand this slow is at rest
VISIT, LEAVE = 0.06, 0.10  # m: the hand is at a stay within VISIT of it, and left past LEAVE
VIEW_TIMES = np.arange(0.0, 3.01, 0.25)  # s ahead at which the forecast hand is drawn


@dataclass(frozen=True)
class KeepClearSettings:
    """What predictive separation needs: the operator's forecast and the speed scale the
    monitor would allow (`ScaleFn`); both None: reactive (monitoring alone). `max_wait`,
    `departure`, `timing` and `reaction_time` (T_r) are `SafetyConfig`'s; `acceleration`, the
    arm's joint acceleration limit [rad/s²] (the ramp of a path timing); `clear_only`: the
    monitor keeps S_p by itself (separation alone), so a wait is taken only where it clears a
    motion (`hrc_drake.motion.clearance.time_around`)."""

    forecast: OperatorForecast | None = None
    scale: ScaleFn | None = None
    max_wait: float = 6.0
    departure: float = 0.15
    timing: str = Timing.WAIT.value
    acceleration: float = 5.0
    reaction_time: float = 0.1
    clear_only: bool = False


class KeepClear:
    """The Supervisor's predictive separation (see the module docstring); a part of
    `hrc_drake.cell.controller.supervisor.Supervisor` that keeps its own record,
    `KeepClearState` (its one writer), and gives the plan follower the plan's waits."""

    def __init__(self, settings: KeepClearSettings):
        self._forecast, self._scale = settings.forecast, settings.scale
        # Fitted to the person once seen at rest: the controller's model of who stands there,
        # learned once per run (a Supervisor runs one simulation).
        self._fitted: OperatorForecast | None = None
        self._max_wait, self._departure = settings.max_wait, settings.departure
        self._path_time = settings.timing == Timing.PATH_TIME
        self._acceleration, self._reaction = settings.acceleration, settings.reaction_time
        self._clear_only = settings.clear_only

    def _anchor(self, s: SupervisorStatus) -> Anchor | None:
        """The indication the forecast starts from: the operator's, or the one predicted."""
        if s.task is None:
            return None
        if s.clear.seen is not None:
            return s.clear.seen
        if s.question.indicated_at is not None:
            return Anchor(s.task.indicated, s.question.indicated_at)
        task = s.turn.committed or s.task.indicated
        return Anchor(task, s.question.asked_at + self._forecast.delay)

    def _offsets(self, s: SupervisorStatus) -> tuple[float, ...]:
        """The forecast's timing spread: narrower once the tracker showed where it is."""
        seen = s.clear.seen
        if seen is not None and (seen.done > 0 or s.clear.visiting is not None):
            return self._forecast.offsets("seen")
        return self._forecast.offsets(s.question.indicated_at is not None)

    def _progress(self, s: SupervisorStatus, hand: np.ndarray, now: float):
        """(the anchor, the stay visited) when the tracked hand reached a stay of the activity
        (pointing, a bin) or left the one it was at; None otherwise."""
        if s.question.indicated_at is None:
            return None
        task = s.task.indicated
        stays = self._forecast.stays(task)
        here = tuple(float(x) for x in hand)
        visiting = s.clear.visiting
        if visiting is not None:
            if np.linalg.norm(hand - stays[visiting].where) > LEAVE:
                return Anchor(task, now, done=visiting + 1, start=here), None
            return None
        first = s.clear.seen.done if s.clear.seen is not None else 0
        for k in range(first, len(stays)):
            if stays[k].what != "rest" and np.linalg.norm(hand - stays[k].where) < VISIT:
                return Anchor(task, now, done=k, start=here), k
        return None

    def _at_last_bin(self, s: SupervisorStatus) -> bool:
        """Whether the tracker shows the hand in the last bin of its fetch: from there it only
        goes back to rest, away from the robot."""
        if s.clear.visiting is None or s.task is None:
            return False
        stays = self._forecast.stays(s.task.indicated)
        fetches = [k for k, stay in enumerate(stays) if stay.what == "fetch"]
        return bool(fetches) and s.clear.visiting == fetches[-1]

    def _fit(self, body: BodySpheres) -> None:
        """Fit the forecast to the person the tracker shows at rest before the first task (the
        controller knows the population's operator, not which hand this one works with or
        where it rests)."""
        if len(body.radii) and np.linalg.norm(body.velocities[0]) < STILL:
            self._forecast = self._forecast.fitted(body)
            self._fitted = self._forecast

    def update(
        self, s: SupervisorStatus, tracked_body: Callable[[], BodySpheres], now: float
    ) -> SupervisorStatus:
        """Re-time the plan when what it was timed for changed, or the body departs from the
        forecast (see the module docstring). `tracked_body()` reads the tracked body."""
        if self._forecast is None:
            return s
        if self._fitted is None and s.step <= 1 and s.question.indicated_at is None:
            self._fit(tracked_body())  # before the operator's first move
        if s.mode != Mode.EXECUTE or s.plan is None:
            return s
        key = (id(s.plan), s.step, s.task.indicated, s.question.indicated_at, s.bolted)
        clear = s.clear
        if key != clear.clear_key:
            s = replace(s, clear=replace(clear, seen=None, visiting=None))
            return self._retime(s, key, now, None)
        if now - clear.checked_at < CHECK_PERIOD:
            return s
        late = now - clear.timed_at >= RETIME_PERIOD
        if late and slip(s.clock.caps, now, s.plan_time(now)) > SLIP:
            s = replace(s, clear=replace(clear, slips=clear.slips + 1))
            return self._retime(s, key, now, None)
        body = tracked_body()
        anchor = self._anchor(s)
        if len(body.radii) == 0 or body.lost_for is not None or anchor is None:
            # A remembered body (`body_memory`: the person lost) says nothing of where they
            # went: no progress or departure is read from it; the monitor holds the arm for it.
            return s
        hand = body.centres[0]
        progress = self._progress(s, hand, now)
        if progress is not None:
            s = replace(s, clear=replace(clear, seen=progress[0], visiting=progress[1]))
            return self._retime(s, key, now, None)
        offsets = self._offsets(s)
        if self._forecast.departure(anchor, hand, now, offsets) <= self._departure:
            return replace(s, clear=replace(clear, checked_at=now))
        if now - clear.timed_at < RETIME_PERIOD:
            return replace(s, clear=replace(clear, checked_at=now))
        moved, left = self._forecast.reanchored(anchor, hand, now)
        s = replace(s, clear=replace(clear, seen=moved, replans=clear.replans + 1))
        unexplained = body if left > self._departure else None
        return self._retime(s, key, now, unexplained)

    def _retime(
        self, s: SupervisorStatus, key: tuple, now: float, unexplained: BodySpheres | None
    ) -> SupervisorStatus:
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
        holds, caps = self._timed(s, now, tau, end_tau, occupancy) if tau < end_tau else ((), ())
        timeline = self._forecast.timeline(anchor)
        view = tuple(tuple(float(x) for x in timeline.at(now + d)) for d in VIEW_TIMES)
        clear = replace(s.clear, clear_key=key, timed_at=now, checked_at=now, forecast_view=view)
        return timed(replace(s, clear=clear), holds, caps)  # the follower's clock takes them

    def _timed(self, s, now: float, tau: float, end_tau: float, occupancy: Occupancy):
        """(holds, speed caps) of the plan from plan time `tau` at `now` to `end_tau`: waits
        at the motions' starts (`time_around`), or each motion's path timing
        (`path_time_around`)."""
        spent = None
        held_since = s.clock.held_since
        if held_since is not None:
            spent = (held_since.tau, now - held_since.since)
        plan = s.plan
        if self._path_time:
            timing = path_time_around(
                plan,
                tau,
                now,
                s.clock.speed,
                occupancy,
                self._scale,
                self._max_wait,
                self._acceleration,
                end_tau,
                spent=spent,
                reaction=self._reaction,
            )
            return timing.holds, timing.caps
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
            clear_only=self._clear_only,
        )
        return holds, ()


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
