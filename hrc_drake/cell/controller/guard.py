"""The guarded descent of a place: the Supervisor watches the wrist load while it lowers a part
onto its seat, and stops pressing when the part meets something before its seat.

A position-controlled arm that lowers a part onto a pocket's rim (the part slid in the fingers,
debris in the pocket) goes on down to where the plan puts the seat: the part is squeezed
between the fingers and the rim until the grasp gives way — smoothly or, with stiffer contact,
in a burst that kicks the wrist off its command (`docs/station.md`, "Guarded descent"). A real
cell watches the load on its wrist instead, as a UR program does with a force-stopped move
(`zero_ftsensor()`, then move until `force()` passes a threshold).

`DescentGuard.watch` is that watch, on `ur3.tcp_force` (the wrist load, world frame): at the
start of the plan's `place` stage (the straight descent from the pre-place pose) it zeroes the
load against the approach (the upward force: every place is from above) with the mean of its
first `ZERO_READINGS` readings, the part hanging still in the fingers; then, while the tool is
still more than `armed_above` above its place, a rise of that load by more than `threshold` is
the part meeting something: the guard trips (`GuardTrip`), naming the joint positions measured
at the last reading whose rise was under half the threshold, just before the contact: the arm
backs off to them, the fingers open, and the arm goes back up its own descent to the pre-place
pose (`Retreat`), whence the Supervisor reads the cell as after any release. Values only; no
Drake.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.motion.plan import Plan, Stage

# Readings averaged to zero the load at the start of a descent (0.1 s at the Supervisor's
# 50 Hz: the arm has just left the pre-place pose, where it rests, and the part hangs still).
ZERO_READINGS = 5


@dataclass(frozen=True)
class GuardSettings:
    """The guard's figures (the Supervisor's `SupervisorLimits.guard`).

    Attributes:
        threshold: N; a rise of the load against the approach past it, while armed, trips the
            guard (the scenario's `run.place_guard`). A seat that takes the part's weight off
            the fingers raises the load by at most that weight (5.6 N for the flange case's
            square flange, measured 0.9 N for an oval one), and it does so at the seat, where
            the guard is disarmed; before it, a descent reads the sensor's noise and the
            part's inertia (under 1 N). A pocket's rim raises it by 10–12 N at the first
            reading and 27–30 N 40 ms later for an oval flange, by 12–48 N at once and 26 N
            held for the square one, at 5e6 and 1e7 Pa alike (`docs/station.md`, "Guarded
            descent").
        armed_above: m; the guard is armed while the tool is more than this above its place (a
            part meets its own seat within the last tenth of a millimetre; a pocket's rim is
            about 3.5 mm above it).
        descent: m; the length of the place's straight descent (`MotionOptions.approach_distance`),
            by which the guard reads how far the tool still is above its place.
        enabled: False: no guard (the descent goes to the plan's end whatever it meets).
    """

    threshold: float = 8.0
    armed_above: float = 0.001
    descent: float = 0.06
    enabled: bool = True


@dataclass(frozen=True)
class GuardState:
    """What the guard has seen of the current descent (reset with every plan)."""

    plan_start: float | None = None  # the plan (its start time) this state belongs to
    readings: tuple[float, ...] = ()  # the loads read to zero the guard with
    zero: float | None = None  # the load against the approach when the descent began [N]
    quiet_q: tuple[float, ...] = ()  # measured q at the last reading under half the threshold
    peak: float = 0.0  # the largest rise seen while armed [N]


@dataclass(frozen=True)
class GuardTrip:
    """The guard tripped: the rise of the load [N], how far the tool still was above its
    place [m], where the arm backs off to (joint positions measured at the last reading
    before the contact) and how far that is above the place [m]."""

    rise: float
    above: float
    q_back: tuple[float, ...]
    above_back: float


def load_against_approach(wrench: np.ndarray) -> float:
    """The load pushing the tool back up [N] from a `ur3.tcp_force` reading (force first, world
    frame): every place lowers the part from above, so the approach is world -z."""
    return float(wrench[2])


def height_above_place(plan: Plan, q: np.ndarray, descent: float) -> float:
    """How far [m] the tool at joint positions `q` is above the end of `plan`'s place descent:
    the descent's `descent` metres scaled by the joint-space distance still to go over the
    descent's whole (the descent is a straight line of a few centimetres at one posture, along
    which the joints move nearly in proportion)."""
    place = plan.segment(Stage.PLACE)
    start, end = plan.positions(place.start), plan.positions(place.end)
    whole = float(np.linalg.norm(end - start))
    if whole < 1e-9:
        return 0.0
    return descent * float(np.linalg.norm(np.asarray(q) - end)) / whole


def tau_at_height(plan: Plan, height: float, descent: float, step: float = 0.002) -> float:
    """The plan time of `plan`'s place descent at which its commanded tool stands `height`
    [m] above the place (the descent's start if it never stands that high), sampled every
    `step` plan seconds from the end back."""
    place = plan.segment(Stage.PLACE)
    for tau in np.arange(place.end, place.start, -step):
        if height_above_place(plan, plan.positions(tau), descent) >= height:
            return float(tau)
    return place.start


@dataclass(frozen=True)
class Retreat:
    """The arm backing off after a guarded stop: it holds at `q_hold` (the measured joint
    positions just before the contact) until `start`, while the fingers open; then it goes
    back up along `plan`'s own descent, from plan time `tau_from` to `tau_to`, smoothly (a
    smoothstep in time), by `end` (simulated seconds)."""

    plan: Plan
    q_hold: tuple[float, ...]
    tau_from: float
    tau_to: float
    start: float
    end: float

    def __deepcopy__(self, memo) -> Retreat:
        return self  # immutable (Drake copies abstract values often)

    def _timing(self, now: float) -> tuple[float, float]:
        """(the plan time the retreat stands at at `now`, its rate [plan s per s]): a
        smoothstep from `tau_from` at `start` to `tau_to` at `end`, still outside them."""
        span = max(self.end - self.start, 1e-9)
        s = float(np.clip((now - self.start) / span, 0.0, 1.0))
        tau = self.tau_from + (self.tau_to - self.tau_from) * s * s * (3.0 - 2.0 * s)
        return tau, (self.tau_to - self.tau_from) * 6.0 * s * (1.0 - s) / span

    def positions(self, now: float) -> np.ndarray:
        """The arm's commanded joint positions at simulated time `now`."""
        if now < self.start:
            return np.asarray(self.q_hold, dtype=float)
        return self.plan.positions(self._timing(now)[0])

    def velocities(self, now: float) -> np.ndarray:
        """The arm's commanded joint velocities at `now`, the time derivative of `positions`:
        the servo is given them as along any plan (a zero velocity command would have its
        damping drag the arm up to 0.05 rad behind, the tracking check's tolerance)."""
        if not self.start <= now <= self.end:
            return np.zeros(len(self.q_hold))
        tau, rate = self._timing(now)
        return self.plan.trajectory.EvalDerivative(tau, 1).ravel() * rate


class DescentGuard:
    """The guarded descent (see the module docstring) with `settings`."""

    def __init__(self, settings: GuardSettings):
        self.settings = settings

    def in_descent(self, plan: Plan, tau: float) -> bool:
        """Whether plan time `tau` is in `plan`'s place descent."""
        place = plan.segment(Stage.PLACE)
        return place.start <= tau < place.end

    def watch(
        self,
        state: GuardState,
        plan: Plan,
        plan_start: float,
        tau: float,
        q: np.ndarray,
        wrench: np.ndarray | None,
    ) -> tuple[GuardState, GuardTrip | None]:
        """One reading (`wrench`, None: no wrist load measured) at plan time `tau` of the plan
        started at `plan_start`, the arm measured at `q`: the guard's next state, and the trip
        if the part has met something before its seat."""
        if state.plan_start != plan_start:
            state = GuardState(plan_start=plan_start)
        settings = self.settings
        if not settings.enabled or wrench is None or not self.in_descent(plan, tau):
            return state, None
        load = load_against_approach(wrench)
        q_now = tuple(float(x) for x in q)
        if state.zero is None:
            readings = (*state.readings, load)
            zero = float(np.mean(readings)) if len(readings) >= ZERO_READINGS else None
            return replace(state, readings=readings, zero=zero, quiet_q=q_now), None
        rise = load - state.zero
        if rise < settings.threshold / 2:
            return replace(state, quiet_q=q_now), None
        above = height_above_place(plan, q, settings.descent)
        if above <= settings.armed_above:
            return state, None  # at its seat: the seat takes the part's weight
        state = replace(state, peak=max(state.peak, rise))
        if rise <= settings.threshold:
            return state, None
        back = state.quiet_q or q_now
        return state, GuardTrip(rise, above, back, height_above_place(plan, back, settings.descent))


__all__ = [
    "ZERO_READINGS",
    "DescentGuard",
    "GuardSettings",
    "GuardState",
    "GuardTrip",
    "Retreat",
    "height_above_place",
    "load_against_approach",
    "tau_at_height",
]
