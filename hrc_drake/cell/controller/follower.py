"""The plan follower: the one writer of the arm's command in the Supervisor's status.

It owns the plan clock (`PlanClock`: the plan, its plan time `tau` and the speed scale), where
the arm holds when it follows no plan (`q_hold`, `opening_hold`) and the back-off after a guarded
stop (`retreat`); `SupervisorStatus.command` reads them. The other parts of the Supervisor ask
for a change with the functions below (start a plan, hold still, back off, jump to the release,
the waits of predictive separation) and never write these fields themselves. `PlanFollower`
advances the clock at every update. Values only; no Drake.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.cell.controller.guard import Retreat
from hrc_drake.cell.controller.supervisor_state import (
    HeldWait,
    Mode,
    SupervisorLimits,
    SupervisorStatus,
)
from hrc_drake.motion.clearance import Hold
from hrc_drake.motion.path_time import SpeedCap, speed_cap
from hrc_drake.motion.plan import Plan


@dataclass(frozen=True)
class Stand:
    """Where the arm stands on its plan (plan time `tau`) and the speed scale it keeps."""

    tau: float
    speed: float


# (status, plan time, speed limit) -> where the arm stands on reaching the pre-place pose
PauseFn = Callable[[SupervisorStatus, float, float], Stand | None]
# (status, plan time, measured opening) -> the plan time where it waits for the fingers
ReleaseWaitFn = Callable[[SupervisorStatus, float, float], float | None]


def hold(s: SupervisorStatus, q: tuple[float, ...], opening: float) -> SupervisorStatus:
    """`s` with the arm following no plan: it holds still at `q`, the gripper at `opening`."""
    return replace(s, clock=replace(s.clock, plan=None), q_hold=q, opening_hold=opening)


def back_off(
    s: SupervisorStatus, retreat: Retreat, q: tuple[float, ...], opening: float
) -> SupervisorStatus:
    """`s` with the arm following no plan but `retreat` (it holds at `q` once back)."""
    return replace(hold(s, q, opening), retreat=retreat)


def backed_off(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with no retreat (the cell was read after it)."""
    return replace(s, retreat=None)


def start(s: SupervisorStatus, plan: Plan, now: float) -> SupervisorStatus:
    """`s` following `plan` from its start at `now`, at the speed scale it has."""
    clock = replace(
        s.clock,
        plan=plan,
        plan_start=now,
        tau=0.0,
        tau_time=now,
        rate=s.clock.speed,
        holds=(),
        caps=(),
        held_since=None,
    )
    return replace(s, clock=clock)


def to_release(s: SupervisorStatus, now: float) -> SupervisorStatus:
    """`s` with the plan moved on to its release at `now` (the part is bolted)."""
    return replace(s, clock=replace(s.clock, tau=s.plan.t_release, tau_time=now))


def timed(
    s: SupervisorStatus, holds: tuple[Hold, ...], caps: tuple[SpeedCap, ...]
) -> SupervisorStatus:
    """`s` with the plan's waits for the operator and its speed caps (predictive separation,
    `hrc_drake.cell.controller.keep_clear`)."""
    return replace(s, clock=replace(s.clock, holds=holds, caps=caps))


def _stand(s: SupervisorStatus, at: Stand, now: float) -> SupervisorStatus:
    """`s` with the arm standing at plan time `at.tau` from `now` (rate 0)."""
    return replace(s, clock=replace(s.clock, tau=at.tau, tau_time=now, speed=at.speed, rate=0.0))


class PlanFollower:
    """Advances the plan clock at every update: `pause` says where the arm stands on reaching
    the pre-place pose (anticipation), `release_wait` where it waits for the fingers to let go
    after a release (fault recovery)."""

    def __init__(self, limits: SupervisorLimits, pause: PauseFn, release_wait: ReleaseWaitFn):
        self._limits, self._pause, self._release_wait = limits, pause, release_wait

    def advance(
        self, s: SupervisorStatus, limit: float, now: float, opening: float
    ) -> SupervisorStatus:
        """Move the plan time to `now`, then ramp the speed scale toward `limit` (no faster
        than the joint acceleration limit allows at the plan's speed) and set the rate on. It
        stands still for bolting, and after a release until the fingers (`opening`) let go."""
        clock = s.clock
        if s.mode != Mode.EXECUTE or clock.plan is None:
            return replace(s, clock=replace(clock, speed=limit))
        plan = clock.plan
        tau = s.plan_time(now)
        paused = self._pause(s, tau, limit)
        if paused is not None:
            return _stand(s, paused, now)
        bolting = s.holding_for_bolts(tau)
        stand = plan.t_in_place if bolting else self._release_wait(s, tau, opening)
        if stand is not None:
            return _stand(s, Stand(stand, limit), now)
        limit = min(limit, speed_cap(clock.caps, now, tau))  # the motion's path timing
        qdot = np.abs(plan.trajectory.EvalDerivative(min(tau, plan.duration), 1)).max()
        step = self._limits.joint_acceleration * self._limits.period / max(qdot, 1e-9)
        speed = float(min(max(limit, clock.speed - step), clock.speed + step))  # np.clip's
        hold_now = clock.hold_at(now) if s.held(now) else None  # the planned wait it stands in
        since = clock.held_since
        if hold_now is not None and (since is None or since.tau != hold_now.tau):
            since = HeldWait(hold_now.tau, now)
        waited = clock.waited + (now - clock.tau_time if hold_now is not None else 0.0)
        clock = replace(
            clock, tau=tau, tau_time=now, speed=speed, rate=speed, waited=waited, held_since=since
        )
        return replace(s, clock=clock)


__all__ = [
    "PlanFollower",
    "Stand",
    "back_off",
    "backed_off",
    "hold",
    "start",
    "timed",
    "to_release",
]
