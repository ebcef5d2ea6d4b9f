"""Time a plan's moves around where a person is forecast to be.

A plan is a chain of arm motions, each from rest to rest (`Plan.motions`). Given a forecast of
the operator's body over time (`Occupancy`: spheres sampled in time, with their velocities) and
the speed scale that speed-and-separation monitoring would allow the robot at a pose, a speed
and a body (`ScaleFn`, the controller's own monitor applied to the forecast), `time_around`
chooses for each motion still to come how long the arm waits at the rest point where it starts:
the shortest wait after which the monitor is forecast never to slow the motion (the motion keeps
the protective separation against the forecast body, starting at each delay of `RUNNING_LATE`),
or, if there is none within `max_wait` (or the caller allows slowing), the wait that costs
least: the wait plus the time the monitor is forecast to add to the motion (`forecast_delay`),
weighed `STOP_PENALTY` times for the braking and restarting it leaves out. With `clear_only`
the arm waits only where a wait clears the motion: a wait that leaves it slowed all the same
is a bet on the forecast delay, which separation alone does not win (see `time_around`). The
arm waits where its motions meet, so every trajectory it follows is still the validated plan;
monitoring stays underneath and acts on the body as measured. The forecast's own timing spread
(`hrc_drake.cell.controller.forecast.OperatorForecast`) covers a person early or late.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrc_drake.motion.plan import Plan

# (q, q̇ at full speed, the gripper's commanded opening [m], the part carried or None, body
# centres k×3, radii k, velocities k×3) -> the speed scale in [0, 1] that separation monitoring
# allows
ScaleFn = Callable[
    [np.ndarray, np.ndarray, float, str | None, np.ndarray, np.ndarray, np.ndarray], float
]
# A forecast slowing costs this many times its lost seconds: the monitor brakes and restarts
# the arm within the joint acceleration limit, which the forecast leaves out, and the person may
# come closer than forecast (our weighting). Measured on the separation benchmark (--seeds 1
# --lean, waits, 8 runs each): at 1.0 the forecast's own person took 38.61 s (0.26 s less) and
# the person the forecast has not seen came inside S_p in 42 samples, with 13 stops of the
# station's safety function (at 1.2: none and none).
STOP_PENALTY = 1.2
SAMPLE = 0.15  # s between the checked poses of a motion
WAIT_STEP = 0.2  # s between the waits tried
# The delays [s] a motion is checked to start at: as planned. A later one (0.3 s) would make the
# timing hold for an arm that comes to its rest point late; on two lean shared-desk runs (follows,
# seed 1, both interaction modes) it changed the assembly time by under 1 % with no violation
# either way, so it is left out.
RUNNING_LATE = (0.0,)
_EPS = 1e-6
# Room [s] over floating-point rounding for a delay known to exceed what the caller needs.
_MARGIN = 1e-9


@dataclass(frozen=True)
class Occupancy:
    """A forecast of the operator's body: at each of `times` (k, ascending, absolute [s]) the
    body's spheres' `centres` (k×n×3) and `velocities` (k×n×3), `radii` (n) [m]. Outside
    [times[0], times[-1]] nothing is forecast (the monitor alone acts there)."""

    times: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray

    def at(self, t: float) -> int | None:
        """The index of the sample nearest `t`, None outside the forecast."""
        times = self.times
        if len(times) == 0 or t < times[0] - _EPS or t > times[-1] + _EPS:
            return None
        i = int(np.searchsorted(times, t))
        if i > 0 and (i == len(times) or t - times[i - 1] <= times[i] - t):
            i -= 1
        return i

    def overlaps(self, start: float, end: float) -> bool:
        """Whether the forecast covers any of [start, end]."""
        return len(self.times) > 0 and start <= self.times[-1] and end >= self.times[0]


@dataclass(frozen=True)
class Hold:
    """The arm waits at plan time `tau` (a rest point) until simulated time `until` [s]."""

    tau: float
    until: float


@dataclass(frozen=True)
class MotionPath:
    """Poses along a plan: plan times `taus` (evenly spaced), with q and q̇ at full speed, the
    gripper's commanded opening and the part carried at each. The opening is the plan's, so that
    the monitor is asked about the gripper as it will be: with the opening unknown it takes the
    fingers over their whole travel (`hrc_drake.cell.separation_pipeline`), which put a carry beside
    the operator's hand at the nut bin at a stop that the monitor, reading the measured opening,
    never made (lean `shared-desk`, follows, seed 0, exact forecast). Holding a part, the
    command is `MotionOptions.grip_squeeze` (2 mm) under its width, so the forecast's fingers
    sit 1 mm inside where they stall on it: a planning figure; the monitor reads the measured
    opening."""

    taus: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    opening: np.ndarray
    carrying: tuple[str | None, ...]


def motion_path(plan: Plan, start: float, end: float, step: float) -> MotionPath:
    """The poses of `plan` over plan times [start, end], `step` apart or closer."""
    count = max(2, int(np.ceil((end - start) / step)) + 1)
    taus = np.linspace(start, end, count)
    q = np.array([plan.trajectory.value(t).ravel() for t in taus])
    qdot = np.array([plan.trajectory.EvalDerivative(t, 1).ravel() for t in taus])
    opening = np.array([plan.gripper_opening(t) for t in taus])
    return MotionPath(taus, q, qdot, opening, tuple(plan.carrying(t) for t in taus))


def remembered(scale: ScaleFn, size: int = 1 << 16) -> ScaleFn:
    """`scale` answering each question it was asked before from memory: the same pose, speed,
    opening, part and forecast sample, known by a digest of their values; the `size` latest
    are kept. A re-timing asks again about the motions still to come, and while the forecast's
    anchor stays, its sample at a time is the same body: on full `shared-desk` (realistic
    sensors, the camera) 2605 of the forecast monitor's 4991 questions were distinct."""
    answers: OrderedDict[bytes, float] = OrderedDict()

    def answer(q, qdot, opening, carrying, centres, radii, velocities) -> float:
        digest = hashlib.blake2b(digest_size=16)
        for values in (q, qdot, centres, radii, velocities):
            digest.update(np.ascontiguousarray(values, dtype=float).tobytes())
        opened = None if opening is None else float(opening)
        digest.update(repr((opened, carrying, len(radii))).encode())
        key = digest.digest()
        if key in answers:
            answers.move_to_end(key)
            return answers[key]
        value = scale(q, qdot, opening, carrying, centres, radii, velocities)
        answers[key] = value
        if len(answers) > size:
            answers.popitem(last=False)
        return value

    return answer


def forecast_delay(
    poses: MotionPath,
    begin: float,
    occupancy: Occupancy,
    scale: ScaleFn,
    memo: dict[tuple[int, int], float] | None = None,
    above: float = np.inf,
) -> float:
    """Seconds the monitor is forecast to add to the motion if it starts at `begin` (absolute):
    the motion played forward in steps of its pose spacing, its plan time advancing at the
    scale the monitor would allow against the forecast body at each moment (a stopped arm
    stays where it stopped until the body leaves). Capped at the forecast's end. `memo` keeps
    the scales already asked, by (pose, forecast sample), for further calls on the same
    `poses` and `occupancy`: the waits a motion tries meet the same pairs again, and each
    costs the monitor's whole assessment. `above`: the caller needs the delay only up to
    there; once the motion has lost more than that (with `_EPS` to spare, for the delay may
    end up to `_EPS` under the time lost so far), the time lost so far, less `_EPS`, is
    returned: a lower bound of the delay, above `above`."""
    offsets = poses.taus - poses.taus[0]
    duration = float(offsets[-1])
    dt = duration / max(len(offsets) - 1, 1)
    if dt <= 0:
        return 0.0
    t, tau = begin, 0.0
    while tau < duration - _EPS:
        k = min(round(tau / dt), len(offsets) - 1)
        i = occupancy.at(t)
        if i is None and t > occupancy.times[-1]:
            break  # past the forecast: nothing slows it any more
        s = 1.0
        if i is not None and np.abs(poses.qdot[k]).max() > _EPS:
            s = memo.get((k, i)) if memo is not None else None
            if s is None:
                s = scale(
                    poses.q[k],
                    poses.qdot[k],
                    poses.opening[k],
                    poses.carrying[k],
                    occupancy.centres[i],
                    occupancy.radii,
                    occupancy.velocities[i],
                )
                if memo is not None:
                    memo[(k, i)] = s
        tau += s * dt
        t += dt
        if s < 1.0 and (t - begin) - tau - _EPS > above + _MARGIN:
            # A scale is at most 1 (`ScaleFn`): time lost is never won back, so the delay is
            # at least this.
            return (t - begin) - tau - _EPS
    return max(0.0, (t - begin) - tau) if tau < duration - _EPS else (t - begin) - duration


def _wait(
    delay: Callable[[float, float], float],
    waits: np.ndarray,
    slowing_ok: bool,
    clear_only: bool,
) -> float:
    """The wait `time_around` takes among `waits` (ascending) before a motion, given
    `delay(wait, above)`: the monitor's forecast delay after `wait`, exact up to `above` (past
    it, any value above it)."""
    if not slowing_ok:
        # The first wait that clears the motion is taken whatever the others cost: it is
        # looked for first, each delay only as far as the motion goes unslowed.
        for wait in waits:
            if delay(wait, _EPS) <= _EPS:
                return float(wait)
        if clear_only:
            return 0.0  # only a clearing wait is taken, and none clears
    best_wait, best_cost = 0.0, np.inf
    for wait in waits:
        if wait >= best_cost - _EPS:
            break  # no later wait, clearing or not, costs less than the best one
        # The delay matters up to where this wait could still cost the least: beyond, it
        # neither clears the motion nor is taken.
        above = _EPS
        if not (clear_only and wait > 0.0):
            above = max(_EPS, (best_cost - _EPS - wait) / STOP_PENALTY)
        lost = delay(wait, above)
        if lost <= _EPS:  # separation forecast to hold: no later wait costs less
            if wait < best_cost - _EPS:
                best_wait = float(wait)
            break
        if clear_only and wait > 0.0:
            continue  # only a wait that clears the motion is taken, against going now
        cost = wait + STOP_PENALTY * lost
        if cost < best_cost - _EPS:
            best_wait, best_cost = float(wait), cost
    return best_wait


def time_around(
    plan: Plan,
    tau: float,
    now: float,
    occupancy: Occupancy,
    scale: ScaleFn,
    max_wait: float,
    end_tau: float | None = None,
    spent: tuple[float, float] | None = None,
    slowing_ok: bool = False,
    clear_only: bool = False,
) -> tuple[Hold, ...]:
    """The waits of the motions of `plan` that start at or after plan time `tau` (the arm is
    there at `now`) and before `end_tau` (None: the plan's end), as `Hold`s (see the module
    docstring). A plan the forecast never slows gets none. `spent`: (plan time, seconds) the arm
    has waited at a rest point already; its motion waits at most `max_wait` in all, so that a
    forecast that keeps moving cannot hold the arm for ever. `slowing_ok`: the caller knows the
    forecast hand only goes away from the arm (the tracker saw it in the last bin of its
    fetch), so each wait is the cheapest, even if the monitor is then forecast to slow the
    motion. `clear_only`: a motion waits only as long as clears it (with `slowing_ok`, only if
    that costs less than going at once); where no wait within `max_wait` clears it, it goes
    at once and the monitor slows it. For separation alone (`safety.contact_speed: 0`), where
    the monitor keeps S_p by itself: there, on lean `shared-desk` runs, the forecast put the
    monitor's delay 2-3 s a task above what the monitor took, and the cheapest waits made the
    assembly 5-11 % longer than monitoring alone (docs/shared-desk.md)."""
    end_tau = plan.duration if end_tau is None else end_tau
    holds: list[Hold] = []
    shift = 0.0
    for motion in plan.motions:
        if motion.start < tau - _EPS or motion.start >= end_tau - _EPS:
            continue
        begin = now + (motion.start - tau) + shift
        if not occupancy.overlaps(begin, begin + motion.duration + max_wait):
            continue
        poses = motion_path(plan, motion.start, motion.start + motion.duration, SAMPLE)
        longest = max_wait
        if spent is not None and abs(spent[0] - motion.start) < _EPS:
            longest = max(0.0, max_wait - spent[1])
        memo: dict[tuple[int, int], float] = {}

        def delay(wait: float, above: float, poses=poses, begin=begin, memo=memo) -> float:
            return max(
                forecast_delay(poses, begin + wait + late, occupancy, scale, memo, above)
                for late in RUNNING_LATE
            )

        waits = np.arange(0.0, longest + _EPS, WAIT_STEP)
        best_wait = _wait(delay, waits, slowing_ok, clear_only)
        if best_wait > 0.0:
            shift += best_wait
            holds.append(Hold(motion.start, begin + best_wait))
    return tuple(holds)


__all__ = [
    "Hold",
    "MotionPath",
    "Occupancy",
    "ScaleFn",
    "forecast_delay",
    "motion_path",
    "remembered",
    "time_around",
]
