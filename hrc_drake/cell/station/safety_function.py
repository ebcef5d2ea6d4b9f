"""The station's separation safety function: what a safety-rated scanner and the robot's own safety
controller do on a real cell, apart from the controller and whatever it believes.

Every `period` it reads what the station measures — the arm's joint state, the gripper's opening,
and the body its safety-rated sensor sees (`safety.sensor`; switched off, the simulated body
itself) — and judges the separation with its own robot model (`RobotEnvelope`, with the
payload the gripper's opening says it holds, `payload`) and the protective separation distance of
`hrc_drake.cell.ssm`, with the person's travel S_h bounded as `safety.human_speed` says (the
tracked speed toward the robot bounded by a hand's acceleration, or ISO 13855's constant
speeds). Its own sampling adds one period to the reaction: S_h spans
T_r + T_s + period and the robot's reaction travel v_r (T_r + period).

It acts through the robot's stop, by gating the arm's command between the controller's
`ur3.position`/`ur3.velocity` and the arm's servo, and reports the safety mode as a UR does
(`SafetyMode`, `safety.mode`; `safety.stop` is 1 in either stop):

- **Safeguard stop** (the separation fell short while the arm moved toward the person faster
  than `safety.contact_speed`, `hrc_drake.cell.ssm.beyond_contact_speed`, or too fast to stop
  short of where the person is): the arm brakes along
  its current direction of motion at the joint acceleration limit, every joint together, and
  holds there; once it has stood still, or every body sphere has been `resume_clearance` beyond
  the S_p of an arm at rest, for `RESTART_DELAY`, it resumes by itself (an arm at rest is
  within the contact speed: it may go on, slowly, while the person stays near); with
  `safety.function.safeguard_reset: manual`, once clear, at a reset instead.
- **Protective stop** (the external protective-stop input, or a robot shape touching the body
  while moving toward it faster than the contact speed, or touching the head): the same brake,
  then it holds until the cause has cleared and someone unlocks — the `safety.unlock` input (a
  button, an LCM message) or the simulated operator `unlock_delay` s after the cause clears —
  never within `UNLOCK_WAIT` of the stop, as a UR.
- **No fresh command** (the `command_stale` input: over the real-time link the arm's commands
  stopped coming, `hrc_drake.cell.link.realtime`): the same brake, a safeguard stop, held while
  the input is on; it resumes `RESTART_DELAY` after fresh commands come again, as a UR's
  controller stops an arm whose servo targets stop coming.
- **No fresh safety sensor frame** (the `sensor_ok` input off: a unit of the safety-rated
  sensor sent no frame within its response time, `hrc_drake.cell.station.safety_sensor`): the
  same, held while the input is off.
- **Reduced**: nothing stopped, a body sphere within `reduced_band` of S_p (the safety sensor's
  warning field), the `safety.reduced` input on, or the TCP past `safety.limits.reduced_plane`.
- **The UR's limits** (`safety.limits`, `hrc_drake.cell.station.ur_limits`): the tool's and the
  elbow's speeds and the arm's momentum, measured from the encoders, against the normal set, or
  in reduced mode the reduced set. A command that would break the set in force is capped (its
  path control); a value over its limit by its tolerance for the detection time is a
  protective stop (cause `robot limit`), unlocked as any other.

After a stop the command reaches the servo through a blend from the held posture, no faster than
`RESUME_SPEED`, so an arm whose controller went on commanding elsewhere does not jump. While the
function holds the arm, nothing the controller commands moves it.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.contact_limits import REGIONS, region_rows
from hrc_drake.cell.ports import NOBODY, BodySpheres, SafetyMode
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.separation_pipeline import (
    SeparationPipeline,
    pipeline_of,
    protective_separation,
)
from hrc_drake.cell.ssm import (
    NEAR_SPEED,
    beyond_contact_speed,
    person_travel,
    protective_distance,
    separation_constant,
    stopping_time,
)
from hrc_drake.cell.station.safety_motion import Blend, Brake, Cap
from hrc_drake.cell.station.ur_limits import UrLimits
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.scenario.safety import SafeguardReset, SafetyConfig

# A UR does not unlock a protective stop within 5 s of it (its dashboard server answers "Cannot
# unlock protective stop until 5s after occurrence").
UNLOCK_WAIT = 5.0  # s
RESUME_SPEED = 0.5  # rad/s: the fastest joint of the blend back to the command (our choice)
# A safeguard stop clears once the separation has been clear this long: a scanner's restart
# delay, and time for the arm to come to rest and for its controller to see the stop and pause
# its own command where the arm stands (our choice; safety scanners offer 0.1-60 s).
RESTART_DELAY = 0.5  # s
MIN_BLEND = 0.2  # s: the shortest blend back to the command (our choice)
# The gripper holds a part when its measured opening lies this close to the part's grasp width
# (our choice). Measured here: the pads close 0.2-0.6 mm inside the width (the oval flange's
# 45 mm reads 44.36-44.38 mm, the square flange's 90 mm 89.77 mm; the RG2 reports 0.1 mm steps),
# and a pick opens the fingers 16 mm wider than the part (`finger_gap` each side).
PAYLOAD_TOLERANCE = 0.002  # m
_N = len(UR3_JOINTS)
# Above this many spheres (a volumetric sensor's voxels) the function first keeps those that can
# matter (`_nearby`); the person model has 27.
PRUNE_ABOVE = 64


def payload(opening: float, widths: Mapping[str, float]) -> tuple[str, ...]:
    """The parts the gripper may hold at its measured `opening`: those whose grasp width
    (`widths`, part -> m) lies within `PAYLOAD_TOLERANCE` of it, in name order (none: empty).
    A safety controller knows its payload from its tool's configuration and the gripper's
    feedback, not from which part the cell believes it carries; where widths alike leave it
    unsure which part, the envelope carries every one of them."""
    return tuple(sorted(p for p, w in widths.items() if abs(opening - w) <= PAYLOAD_TOLERANCE))


class StopCause(enum.StrEnum):
    """Why the safety function stopped the arm."""

    SEPARATION = "separation"  # safeguard stop
    CONTACT = "contact"  # protective stop: a robot shape touched the body while moving
    EXTERNAL = "external input"  # protective stop: the robot's protective-stop input
    STALE_COMMAND = "no fresh command"  # safeguard stop: the commands stopped coming
    STALE_SENSOR = "no fresh safety sensor frame"  # safeguard stop: a unit stopped sending
    LIMIT = "robot limit"  # protective stop: the measured arm broke the UR's limit set


# The causes of a safeguard stop, which clears by itself; the others are protective stops.
SAFEGUARD_CAUSES = (StopCause.SEPARATION, StopCause.STALE_COMMAND, StopCause.STALE_SENSOR)


@dataclass(frozen=True)
class SeparationVerdict:
    """One judgement of the separation.

    Attributes:
        margin: least gap − S_p at the measured speed [m] where the robot moves toward the
            person faster than `safety.contact_speed` (inf: nobody tracked, or none does).
        clear: every body sphere is `resume_clearance` beyond the S_p of an arm at rest.
        reduced: some sphere is within `reduced_band` of S_p.
        contact: a robot shape touches a body sphere moving toward it faster than the contact
            speed, or touches the head: a contact power and force limiting does not permit.
        moving: a joint moves faster than `safety.moving_speed`.
    """

    margin: float = float("inf")
    clear: bool = True
    reduced: bool = False
    contact: bool = False
    moving: bool = False


def judge_separation(
    envelope: RobotEnvelope | SeparationPipeline,
    q: np.ndarray,
    v: np.ndarray,
    opening: float,
    carrying: str | tuple[str, ...] | None,
    body: BodySpheres,
    config: SafetyConfig,
    joint_acceleration: float,
    period: float,
) -> SeparationVerdict:
    """The safety function's judgement (see the module docstring) of the arm at measured `q`,
    `v`, the gripper at `opening` holding `carrying`, beside `body`; `envelope`: the station's
    model of the robot, or its `SeparationPipeline`."""
    moving = bool(np.abs(v).max(initial=0.0) > config.moving_speed)
    if len(body.radii) == 0:
        return SeparationVerdict(moving=moving)
    function = config.function
    pipeline = pipeline_of(envelope)
    t_s = stopping_time(v, joint_acceleration)
    if len(body.radii) > PRUNE_ABOVE:
        body = _nearby(pipeline.robot(q, opening, carrying), v, body, config, period, t_s)
        if len(body.radii) == 0:
            return SeparationVerdict(moving=moving)
    geometry = pipeline.pairs(q, opening, carrying, body)
    gap = geometry.gap
    v_r = np.maximum(0.0, geometry.robot_speeds(np.asarray(v, dtype=float)[None, :])[0])
    s_p = protective_separation(geometry, v_r, t_s, config, period)
    travel = person_travel(geometry.person_speed(), gap, config.reaction_time + period, config)
    at_rest = travel + separation_constant(config)
    short, beyond = gap - s_p, beyond_contact_speed(v_r, config.contact_speed, body)
    # Slow enough is not enough: the arm must also be able to stop short of the person where
    # they are now (power and force limiting permits them coming into it, not it into them).
    unstoppable = gap < protective_distance(0.0, v_r, t_s, config, period)
    beyond = beyond | unstoppable
    return SeparationVerdict(
        margin=float(np.where(beyond, short, np.inf).min()),
        clear=bool((gap - at_rest).min() >= function.resume_clearance),
        reduced=bool(short.min() < function.reduced_band),
        contact=bool((beyond & (gap <= 0.0)).any()),
        moving=moving,
    )


def _nearby(robot, v, body: BodySpheres, config: SafetyConfig, period: float, t_s: float):
    """The spheres of `body` that can bear on the verdict: those that may lie within S_p and
    the wider of the reduced band and the resume clearance, S_p bounded above by the person's
    fastest travel and the robot's fastest point (`PosedRobot.within`). The rest are farther
    than any S_p, band or clearance the verdict compares them with."""
    person = max(NEAR_SPEED, float(np.linalg.norm(body.velocities, axis=1).max(initial=0.0)))
    s_h = person * (config.reaction_time + t_s + period)
    band = max(config.function.reduced_band, config.function.resume_clearance)

    def reach(fastest: float) -> float:
        return float(protective_distance(s_h, fastest, t_s, config, period)) + band

    keep = robot.within(v, body, reach)
    if len(keep) == len(body.radii):
        return body
    rows = region_rows(body)[keep]
    order = np.argsort(rows, kind="stable")
    keep, rows = keep[order], rows[order]
    ends = np.searchsorted(rows, np.arange(len(REGIONS) + 1))
    groups = tuple((int(ends[g]), int(ends[g + 1])) for g in range(len(REGIONS)))
    return replace(
        body,
        centres=body.centres[keep],
        radii=body.radii[keep],
        velocities=body.velocities[keep],
        groups=groups if len(body.groups) == len(REGIONS) else body.groups,
    )


@dataclass(frozen=True)
class SafetyFunctionLog:
    """What the safety function did over a run (`simulate --json` `safety.function`)."""

    safeguard_stops: int = 0
    protective_stops: int = 0
    unlocks: int = 0
    stopped_time: float = 0.0  # s the function held or braked the arm
    reduced_time: float = 0.0  # s in the reduced mode
    capped_time: float = 0.0  # s the path control held the arm below its command's speed
    events: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The JSON-able figures and events (the times in s, to the millisecond)."""
        return {
            "safeguard_stops": self.safeguard_stops,
            "protective_stops": self.protective_stops,
            "unlocks": self.unlocks,
            "stopped_time": round(self.stopped_time, 3),
            "reduced_time": round(self.reduced_time, 3),
            "capped_time": round(self.capped_time, 3),
            "events": list(self.events),
        }

    @classmethod
    def from_json(cls, data: dict) -> SafetyFunctionLog:
        """The log `to_json` gave, its times to the millisecond as `to_json` rounds them
        (KeyError or TypeError for a field missing or unknown)."""
        return cls(**{**data, "events": tuple(data["events"])})


@dataclass(frozen=True)
class SafetyFunctionState:
    """The function's state: its mode, why and since when it stopped, the brake it follows, the
    blend back to the command, when a protective stop's cause cleared, the UR's limits (the
    path control's cap, since when a limit has been broken, since when reduced mode held), and
    its log."""

    mode: SafetyMode = SafetyMode.NORMAL
    cause: StopCause | None = None
    since: float = 0.0
    brake: Brake | None = None
    blend: Blend | None = None
    cleared_at: float | None = None  # when the stop's cause cleared (None: it has not)
    cap: Cap | None = None
    over_since: float | None = None
    reduced_since: float = 0.0
    log: SafetyFunctionLog = SafetyFunctionLog()

    def __deepcopy__(self, memo) -> SafetyFunctionState:
        return self


def _stop(state: SafetyFunctionState, cause: StopCause, brake: Brake, now: float, why: str = ""):
    """`state` stopped for `cause` (in words, `why`) at `now`, braking by `brake` (an arm
    already braking keeps its brake; a protective stop overrides a safeguard stop)."""
    protective = cause not in SAFEGUARD_CAUSES
    log = state.log
    log = replace(
        log,
        safeguard_stops=log.safeguard_stops + int(not protective),
        protective_stops=log.protective_stops + int(protective),
        events=(*log.events, f"{now:.2f}: {_words(cause)}{why and ': ' + why}"),
    )
    return replace(
        state,
        mode=SafetyMode.PROTECTIVE_STOP if protective else SafetyMode.SAFEGUARD_STOP,
        cause=cause,
        since=now,
        brake=state.brake if state.mode.stopped else brake,
        blend=None,
        cleared_at=None,
        cap=None,
        log=log,
    )


def _words(cause: StopCause) -> str:
    if cause == StopCause.SEPARATION:
        return "safeguard stop: the separation fell short"
    if cause in (StopCause.STALE_COMMAND, StopCause.STALE_SENSOR):
        return f"safeguard stop: {cause.value}"
    return f"protective stop: {cause.value}"


def _timed(state: SafetyFunctionState, period: float) -> SafetyFunctionLog:
    """`state`'s log with the last period counted to its mode, and to the cap if it held."""
    log = state.log
    if state.mode.stopped:
        log = replace(log, stopped_time=log.stopped_time + period)
    elif state.mode == SafetyMode.REDUCED:
        log = replace(log, reduced_time=log.reduced_time + period)
    if state.cap is not None:
        log = replace(log, capped_time=log.capped_time + period)
    return log


def step(
    state: SafetyFunctionState,
    verdict: SeparationVerdict,
    external: bool,
    unlock: bool,
    brake: Brake,
    now: float,
    config: SafetyConfig,
    period: float,
    simulated_unlock: bool = True,
    stale: bool = False,
    blind: bool = False,
    limit: str | None = None,
    reduced: bool = False,
) -> SafetyFunctionState:
    """One period of the function (see the module docstring): the next state from the
    separation `verdict`, the `external` protective-stop input, the `unlock` input, the
    `stale` command input, the `blind` input (the safety sensor's frames stopped coming), the
    UR's `limit` broken (its words; None: none), the `reduced` input and the `brake` the arm
    would follow if it stopped now; with `simulated_unlock` the simulated operator also
    unlocks, `safety.function.unlock_delay` after the cause clears."""
    function = config.function
    state = replace(state, log=_timed(state, period))
    if external:
        if state.cause != StopCause.EXTERNAL:
            state = _stop(state, StopCause.EXTERNAL, brake, now)
        return replace(state, cleared_at=None)
    if stale or blind:
        if not state.mode.stopped:
            cause = StopCause.STALE_COMMAND if stale else StopCause.STALE_SENSOR
            return _stop(state, cause, brake, now)
        # Held, whatever stopped it: a protective stop is not unlocked meanwhile.
        stopped = state.mode == SafetyMode.SAFEGUARD_STOP
        return replace(state, cleared_at=None) if stopped else state
    if limit is not None and state.mode != SafetyMode.PROTECTIVE_STOP:
        return _stop(state, StopCause.LIMIT, brake, now, limit)
    if verdict.contact and verdict.moving and state.mode != SafetyMode.PROTECTIVE_STOP:
        return _stop(state, StopCause.CONTACT, brake, now)
    if state.mode == SafetyMode.PROTECTIVE_STOP:
        delay = function.unlock_delay if simulated_unlock else -1.0
        return _unlocked(state, verdict, unlock, now, delay)
    if state.mode == SafetyMode.SAFEGUARD_STOP:
        delay = function.unlock_delay if simulated_unlock else -1.0
        return _safeguarded(state, verdict, unlock, now, function.safeguard_reset, delay)
    if function.enabled and verdict.moving and verdict.margin < 0.0:
        return _stop(state, StopCause.SEPARATION, brake, now)
    reduced = reduced or (function.enabled and verdict.reduced)
    since = state.reduced_since if state.mode == SafetyMode.REDUCED else now
    mode = SafetyMode.REDUCED if reduced else SafetyMode.NORMAL
    return replace(state, mode=mode, reduced_since=since)


def _safeguarded(state, verdict: SeparationVerdict, unlock: bool, now: float, reset, delay):
    """A safeguard stop: held while the arm moves inside S_p; once clear, it resumes by itself
    after `RESTART_DELAY` (`reset` auto), or at the `unlock` input or the simulated operator's
    reset `delay` s after it cleared (manual; a negative delay: never)."""
    if verdict.moving and not verdict.clear:
        return replace(state, cleared_at=None)
    if state.cleared_at is None:
        return replace(state, cleared_at=now)
    if reset == SafeguardReset.MANUAL:
        operator = delay >= 0 and now >= state.cleared_at + delay - 1e-9
        return _resumed(state, now, "safeguard stop reset") if unlock or operator else state
    if now >= state.cleared_at + RESTART_DELAY - 1e-9:
        return _resumed(state, now, "safeguard stop cleared")
    return state


def _unlocked(state, verdict: SeparationVerdict, unlock: bool, now: float, delay: float):
    """A protective stop after its external cause is off: it waits for its cause to clear (a
    contact: the separation clear), then for the unlock, never within UNLOCK_WAIT."""
    cleared = state.cleared_at
    if cleared is None and (state.cause in (StopCause.EXTERNAL, StopCause.LIMIT) or verdict.clear):
        state = replace(state, cleared_at=now)
        cleared = now
    if cleared is None or now < state.since + UNLOCK_WAIT - 1e-9:
        return state
    operator = delay >= 0 and now >= cleared + delay - 1e-9
    if not (unlock or operator):
        return state
    state = replace(state, log=replace(state.log, unlocks=state.log.unlocks + 1))
    return _resumed(state, now, "protective stop unlocked")


def _resumed(state: SafetyFunctionState, now: float, words: str) -> SafetyFunctionState:
    """Back to normal at `now`, blending from where the brake holds the arm to the command."""
    held, _ = state.brake.at(now)
    log = replace(state.log, events=(*state.log.events, f"{now:.2f}: {words}: resumes"))
    return replace(
        state,
        mode=SafetyMode.NORMAL,
        cause=None,
        brake=None,
        blend=Blend(now, held, MIN_BLEND),
        cleared_at=None,
        log=log,
    )


class SafetyFunction(LeafSystem):
    """The station's safety function (see the module docstring).

    Input ports: `ur3.position`, `ur3.velocity` (the controller's command, 6 each),
    `ur3.state` (measured, 12), `rg2.state` (measured opening and rate, 2; the opening also
    says the payload, `payload` of the parts' grasp `widths`), `operator.body` (BodySpheres),
    `external_stop` (1: the robot's protective-stop input), `safety.unlock` (1: unlock a
    protective stop; connected, a person unlocks there and only there; unconnected, the
    simulated operator does), `command_stale` (1 while the arm's commands have stopped coming;
    unconnected, never), `sensor_ok` (0 while the safety sensor's frames are stale;
    unconnected, always 1), `safety.reduced` (1: the UR's reduced-mode input; unconnected, 0).
    Output ports: `desired_state` (12, for the arm's servo), `safety.stop` (1), `safety.mode`
    (1, the `SafetyMode` code). Updated every `period`."""

    def __init__(
        self,
        envelope: RobotEnvelope | SeparationPipeline,
        config: SafetyConfig,
        joint_acceleration: float,
        period: float,
        widths: Mapping[str, float],
    ):
        super().__init__()
        self._pipeline, self._config, self._widths = pipeline_of(envelope), config, dict(widths)
        self._ur = UrLimits(self._pipeline.envelope, config.limits, period)
        self._acc, self._period = joint_acceleration, period
        self._position = self.DeclareVectorInputPort("ur3.position", _N)
        self._velocity = self.DeclareVectorInputPort("ur3.velocity", _N)
        self._arm = self.DeclareVectorInputPort("ur3.state", 2 * _N)
        self._gripper = self.DeclareVectorInputPort("rg2.state", 2)
        self._body = self.DeclareAbstractInputPort("operator.body", AbstractValue.Make(NOBODY))
        self._external = self.DeclareVectorInputPort("external_stop", 1)
        self._unlock = self.DeclareVectorInputPort("safety.unlock", 1)
        self._stale = self.DeclareVectorInputPort("command_stale", 1)
        self._sensor_ok = self.DeclareVectorInputPort("sensor_ok", 1)
        self._reduced = self.DeclareVectorInputPort("safety.reduced", 1)
        self._state = self.DeclareAbstractState(AbstractValue.Make(SafetyFunctionState()))
        command = {self._position.ticket(), self._velocity.ticket()}
        ticket = {self.abstract_state_ticket(self._state), self.time_ticket()}
        self.DeclareVectorOutputPort(
            "desired_state",
            BasicVector(2 * _N),
            self._calc_desired,
            prerequisites_of_calc=command | ticket,
        )
        self.DeclareVectorOutputPort(
            "safety.stop", BasicVector(1), self._calc_stop, prerequisites_of_calc=ticket
        )
        self.DeclareVectorOutputPort(
            "safety.mode", BasicVector(1), self._calc_mode, prerequisites_of_calc=ticket
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def state(self, context) -> SafetyFunctionState:
        """The function's state in this system's `context`."""
        return context.get_abstract_state(self._state).get_value()

    def _command(self, context, state: SafetyFunctionState, now: float):
        """The controller's command, through the blend back to it after a stop."""
        q, v = self._position.Eval(context), self._velocity.Eval(context)
        return (q, v) if state.blend is None else state.blend.of(now, q, v)

    def _calc_desired(self, context, output) -> None:
        state, now = self.state(context), context.get_time()
        if state.brake is not None:
            q, v = state.brake.at(now)
        elif state.cap is not None:
            q, v = state.cap.at(now)
        else:
            q, v = self._command(context, state, now)
        output.SetFromVector(np.concatenate([q, v]))

    def _calc_stop(self, context, output) -> None:
        output.SetFromVector([1.0 if self.state(context).mode.stopped else 0.0])

    def _calc_mode(self, context, output) -> None:
        output.SetFromVector([float(self.state(context).mode)])

    def _update(self, context, state) -> None:
        x = self._arm.Eval(context)
        q, v = x[:_N], x[_N:]
        opening = float(self._gripper.Eval(context)[0])
        verdict = judge_separation(
            self._pipeline,
            q,
            v,
            opening,
            payload(opening, self._widths),
            self._body.Eval(context),
            self._config,
            self._acc,
            self._period,
        )
        # A person at the unlock input (a pendant's button) unlocks; without one, the simulated
        # operator does, after `unlock_delay`.
        pendant = self._unlock.HasValue(context)
        unlock = pendant and self._unlock.Eval(context)[0] > 0.5
        now = context.get_time()
        stale = self._stale.HasValue(context) and self._stale.Eval(context)[0] > 0.5
        blind = self._sensor_ok.HasValue(context) and self._sensor_ok.Eval(context)[0] < 0.5
        over_since, broken = self._ur.watch(self.state(context), q, v, opening, now)
        reduced = self._reduced.HasValue(context) and self._reduced.Eval(context)[0] > 0.5
        new = step(
            self.state(context),
            verdict,
            self._external.Eval(context)[0] > 0.5,
            unlock,
            Brake(now, np.array(q), np.array(v), self._acc),
            now,
            self._config,
            self._period,
            simulated_unlock=not pendant,
            stale=stale,
            blind=blind,
            limit=broken,
            reduced=reduced or self._ur.triggered(q, opening),
        )
        if new.blend is not None and new.blend.start == now:
            # The smoothstep's peak rate is 1.5 times its mean.
            far = float(np.abs(self._position.Eval(context) - new.blend.q).max(initial=0.0))
            new = replace(
                new, blend=replace(new.blend, duration=max(MIN_BLEND, 1.5 * far / RESUME_SPEED))
            )
        elif new.blend is not None and now >= new.blend.start + new.blend.duration:
            new = replace(new, blend=None)
        cap = None
        if new.brake is None:  # the path control caps the command the servo would follow
            q_cmd, v_cmd = self._command(context, new, now)
            reduced = new.mode == SafetyMode.REDUCED
            cap = self._ur.cap(new.cap, reduced, q_cmd, v_cmd, q, opening, now)
        state.get_mutable_abstract_state(self._state).set_value(
            replace(new, over_since=over_since, cap=cap)
        )


__all__ = [
    "MIN_BLEND",
    "RESTART_DELAY",
    "RESUME_SPEED",
    "SAFEGUARD_CAUSES",
    "UNLOCK_WAIT",
    "Blend",
    "Brake",
    "SafetyFunction",
    "SafetyFunctionLog",
    "SafetyFunctionState",
    "SeparationVerdict",
    "StopCause",
    "judge_separation",
    "step",
]
