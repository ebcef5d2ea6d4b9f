"""Speed and separation monitoring (ISO/TS 15066 §5.5.4) in the controller, from what a real cell
measures.

The monitor belongs to the controller and serves its planning: it slows the plan so that the
station's safety function (`hrc_drake.cell.station.safety_function`), which executes the stops,
need not. It reads what a real cell offers: the arm's measured joint state (`ur3.state_estimated`),
optionally the gripper's measured opening (`rg2.state_measured`), the tracked operator body
(`operator.body`, world-frame spheres with velocities), and what the Supervisor is about to do
(`intent`: the plan's joint velocities at full speed, the part it carries). Nothing comes from the
simulator's SceneGraph or plant state.

Like a real controller it has its own kinematic model of the robot (`RobotEnvelope`): the UR3,
the gripper and the part it carries as convex primitives posed from the measured joint state.

Each step is one forward-kinematics pass at the measured q, the distance from every body sphere to
every robot shape at once in numpy (the distance of the sphere's centre minus its radius; a chain
of spheres is thinner than its capsule between spheres, so the radius counts `1 + CHAIN_GAP`
times), and for every such pair the robot's velocity toward the sphere at the shape's nearest
point, from its link's spatial velocity (the link's spatial velocity Jacobian, from the posed joint
axes of the serial arm, times the measured v and times the plan's q̇ at full speed). Every pair is
assessed, not only each sphere's nearest shape: a farther shape moving fast toward the sphere can
need more room. With them it evaluates the protective separation distance of `hrc_drake.cell.ssm`
with S_h = v_h (T_r + T_s) (or the hand's bounded travel, `SafetyConfig.hand_acceleration`).

`speed_limit` (the Supervisor's input) is the largest speed scale s ∈ [0, 1] of the plan at which
every pair keeps at least S_p(s) + `slow_band`, with the plan's own velocities scaled by s (S_p is
quadratic in s): 1 is full speed, 0 a stop. The band keeps room for the monitor's lag and for a
hand that starts to move; but once the plan has stood in it for `STAND_BEFORE_CREEP` beside a body
that stands still, it creeps on at `BAND_CREEP` at most, at a share (`CREEP_SHARE`) of the speed
that keeps S_p(s) itself, for as long as the body stays still (`BandCreep`): else a person who
waits beside the path held the robot for as long as they waited. The monitor's update logs each
period (`SafetyLog`): least separation, least margin (separation − S_p with the measured
velocities) while the robot moves, violations (steps where the robot moved with separation < S_p
under its own command: its plan moving it, or stopping it from a move), steps moved closer than S_p
by an outside force (`imposed`: a standstill commanded, or a joint IMPOSED_SPEED faster than
commanded: the arm pushed; counted apart, never hidden), body contacts, and the time spent slowed
and stopped while the plan moves the arm.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.contact_limits import touchable
from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.separation_pipeline import (
    BodyPairs,
    SeparationPipeline,
    pipeline_of,
    protective_separation,
)
from hrc_drake.cell.ssm import (
    FAR_SPEED,
    IMPOSED_SPEED,
    NEAR_DISTANCE,
    NEAR_SPEED,
    beyond_contact_speed,
    contact_speeds,
    entry_scales,
    person_travel,
    separation_constant,
    stopping_time,
)
from hrc_drake.cell_models import CellDesign
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.scenario.safety import HumanSpeed, SafetyConfig

# The plan moves toward a person closer than S_p at this share of `safety.contact_speed` at
# most: the servo lags its command and a point's speed is not linear in the joints' (our
# choice).
CONTACT_SHARE = 0.8
# The plan allows for ISO 13855's near speed this much farther out than the standard's 0.5 m:
# S_h steps up there, and the arm needs time to slow (our choice).
NEAR_AHEAD = 0.1  # m
_SLOWEST = 1e-9  # m/s: a point this slow toward the person never limits the plan
# A planned scale stands this far under its root, so that rounding never puts S_p past the room.
_ROOT_SLACK = 1e-9
# Controller periods a limit set now takes to govern what the safety function judges: it
# reaches the arm at the Supervisor's next update, the function judges a period after, and
# meanwhile the speed scale ramps toward it at the joint acceleration limit. With the creep held
# to stopping short of the person on T_r + sampling alone, the function stopped the arm 69
# times in 8 runs of monitoring alone on `shared-desk` (benchmarks/reports/separation_standard.md).
MONITOR_LAG = 2
# Beside a body that stands still, a plan held in `slow_band` goes on at most at this share of
# its speed, as long as it keeps S_p(s) itself (our choice: the ramp down from it takes a few
# millimetres). Still: every sphere slower than STILL_SPEED; held first for STAND_BEFORE_CREEP.
# Creeping in the band at once cost the band its room: on lean `shared-desk` (separation alone)
# the station's safety function then stopped the arm 77 times in 8 runs of monitoring alone,
# and the unseen person came inside S_p 57 times, where both were 0.
BAND_CREEP = 0.1
# ... and at this share of the speed that keeps S_p(s) exactly: the servo overshoots its command
# by a few per cent, and each 0.01 rad/s more adds 2 ms to T_s and 4 mm to S_h at 2.0 m/s (at
# the exact root the station's safety function stopped the arm 6 times in the 8 runs of
# monitoring alone and 20 times in those against the unseen person). Still is judged on the
# tracked velocities, so with `sensors: realistic` (5 cm/s of noise) the creep rarely starts.
CREEP_SHARE = 0.5
STILL_SPEED = 0.05  # m/s
STAND_BEFORE_CREEP = 1.0  # s
# A plan allowed slower than this share of its speed stops instead: the creep toward a person
# slows in proportion to the room left, so it would come ever closer and never stand (our
# choice).
SLOWEST_SCALE = 0.02


@dataclass(frozen=True)
class SeparationReading:
    """One step's assessment.

    Attributes:
        separation: least distance robot–body [m] (inf: nothing measured).
        margin: least separation − S_p with the measured velocities [m].
        short: the separation falls short of S_p where the robot moves toward the person
            faster than `safety.contact_speed` (`hrc_drake.cell.ssm.beyond_contact_speed`).
        limit: the speed scale allowed (see the module docstring).
        moving: a robot joint moves faster than `SafetyConfig.moving_speed`.
        imposed: a joint moves faster than commanded by more than IMPOSED_SPEED: the arm is
            moved by an outside force (a push), not by its servo.
        stale: the body reading is older than the tracker's bound (`BodyAge.stale_after`):
            no body is seen, and the plan stops (`limit` 0).
        lost: the body is a person the tracker lost, grown to where they could be
            (`body_memory`): it limits the plan; the log counts no distance of it.
    """

    separation: float = float("inf")
    margin: float = float("inf")
    short: bool = False
    limit: float = 1.0
    moving: bool = False
    imposed: bool = False
    stale: bool = False
    lost: bool = False

    def __deepcopy__(self, memo) -> SeparationReading:
        return self  # immutable once made (Drake copies abstract values often)


@dataclass(frozen=True)
class SafetyLog:
    """The run's safety figures, accumulated step by step (`simulate --json` `safety`)."""

    steps: int = 0
    min_separation: float = float("inf")
    min_margin: float = float("inf")
    violations: int = 0
    imposed: int = 0  # moved closer than S_p while the robot commanded a standstill
    body_contacts: int = 0
    slowed_time: float = 0.0
    stopped_time: float = 0.0
    ssm_delay: float = 0.0  # s the plan fell behind while monitoring slowed or stopped it
    limiting: bool = False  # monitoring slowed the plan and its speed is not back yet

    def __deepcopy__(self, memo) -> SafetyLog:
        return self  # immutable once made

    def to_json(self) -> dict:
        """The JSON-able figures (distances in m, rounded to 0.1 mm; None: never measured)."""

        def finite(x: float) -> float | None:
            return round(float(x), 4) if np.isfinite(x) else None

        return {
            "min_separation": finite(self.min_separation),
            "min_margin": finite(self.min_margin),
            "violations": self.violations,
            "imposed": self.imposed,
            "body_contacts": self.body_contacts,
            "slowed_time": round(self.slowed_time, 3),
            "stopped_time": round(self.stopped_time, 3),
            "ssm_delay": round(self.ssm_delay, 3),
        }


@dataclass(frozen=True)
class BandCreep:
    """Whether the plan may creep on within the slow band (`assess`'s `band_creep`): `on` once
    it has stood there `STAND_BEFORE_CREEP` (`stood` [s]) beside a body that stands still, and
    until the body moves, the plan stops moving or the arm is out of the band."""

    stood: float = 0.0
    on: bool = False

    def __deepcopy__(self, memo) -> BandCreep:
        return self  # immutable once made


def band_creep_step(
    creep: BandCreep,
    reading: SeparationReading,
    intent: MotionIntent,
    body: BodySpheres,
    period: float,
) -> BandCreep:
    """`creep` a monitor period later, after `reading` (made with `creep`) of `body`."""
    speeds = np.linalg.norm(np.asarray(body.velocities, dtype=float).reshape(-1, 3), axis=1)
    seen = not (reading.stale or reading.lost)  # a lost person is not known to stand still
    still = len(speeds) > 0 and seen and float(speeds.max()) < STILL_SPEED
    if not (still and plan_moves(intent)):
        return BandCreep()
    if creep.on:
        return creep if reading.limit <= BAND_CREEP else BandCreep()
    stood = creep.stood + period if reading.limit == 0.0 else 0.0
    return BandCreep(stood, stood >= STAND_BEFORE_CREEP - 1e-9)


def planned_distance(s, v_h, gap, v_r1, t_rp: float, t_s1: float, config: SafetyConfig):
    """S_p(s) [m] per pair of a plan at speed scale `s` (see `planned_scales`)."""
    travel = person_travel(v_h, gap, t_rp + t_s1 * s, config, NEAR_DISTANCE + NEAR_AHEAD)
    return travel + v_r1 * s * t_rp + v_r1 * s * s * t_s1 / 2 + separation_constant(config)


def planned_scales(v_h, gap, v_r1, t_rp: float, t_s1: float, config: SafetyConfig, room):
    """Per pair, the largest speed scale s ∈ [0, 1] of the plan at which S_p(s) ≤ `room`
    (`planned_distance`: the person's travel over T_r + sampling + T_s(s), T_s(s) = s `t_s1`,
    from their tracked speed toward the robot `v_h`, the robot's speed toward them s `v_r1`
    over T_r + sampling (`t_rp`) and its stopping distance), 0 where none is. The plan takes
    ISO 13855's near speed `NEAR_AHEAD` sooner than 0.5 m, so that it slows before the safety
    function's S_h steps up there.

    In closed form: S_p(s) = max(S_h(w), 0) + X(s) with the window w = t_rp + t_s1 s and the
    robot's part X(s) = C + v_r1 t_rp s + v_r1 t_s1 s² / 2. S_h(w) (`bounded_travel`) is
    v0 w + a w² / 2 until the hand reaches its cap c at w = R = (c - v0) / a, then linear at c;
    convex, and so is S_h(w(s)) + X(s). S_p(s) ≤ room holds where both S_h + X ≤ room and
    X ≤ room: from s = 0 up to the smaller of their largest roots (S_p grows with s)."""
    return _PlannedScales(v_h, gap, v_r1, t_rp, t_s1, config).scales(room)


class _PlannedScales:
    """`planned_scales`' terms that do not depend on the room, once for the rooms `banded_scales`
    asks about: its closed form's arithmetic and `planned_distance`'s, in the same order."""

    def __init__(self, v_h, gap, v_r1, t_rp: float, t_s1: float, config: SafetyConfig):
        v0, gap, v_r1 = (np.asarray(x, dtype=float) for x in (v_h, gap, v_r1))
        self.const = const = separation_constant(config)
        self.r1, self.r2 = r1, r2 = v_r1 * t_rp, v_r1 * t_s1 / 2.0
        cap = np.where(gap < NEAR_DISTANCE + NEAR_AHEAD, NEAR_SPEED, FAR_SPEED)
        if config.human_speed == HumanSpeed.CONSTANT:
            reach = np.zeros_like(v0)  # at the cap from the start: S_h = c w
            accel = 0.0
        else:
            accel = config.hand_acceleration
            cap = np.maximum(cap, v0)  # a hand already faster keeps its speed
            reach = (cap - v0) / accel
        # S_h + X on each piece of the window as c0 + c1 s + c2 s²: rising (w ≤ R), then at
        # the cap.
        self.rising = rising = (
            v0 * t_rp + accel * t_rp * t_rp / 2.0 + const,
            (v0 + accel * t_rp) * t_s1 + r1,
            accel * t_s1 * t_s1 / 2.0 + r2,
        )
        self.at_cap = (
            v0 * reach + accel * reach * reach / 2.0 + cap * (t_rp - reach) + const,
            cap * t_s1 + r1,
            r2,
        )
        # The rising piece holds the root where the cap comes only past it (or past s = 1);
        # t_s1 is one number, so only its side of the choice is worked out.
        s_cap = (reach - t_rp) / t_s1 if t_s1 > 0.0 else np.where(reach > t_rp, np.inf, -np.inf)
        at = np.minimum(np.maximum(s_cap, 0.0), 1.0)
        self.capped = s_cap > 0.0, s_cap >= 1.0
        self.rising_at = rising[0] + rising[1] * at + rising[2] * at * at
        # S_p(0) (`planned_distance`) with the hand's travel from the terms above.
        self._hand = v0, cap, reach, t_rp, t_s1, config
        zero = v_r1 * 0.0
        travel = self._travel(v0, cap, reach, t_rp + t_s1 * 0.0, config)
        self.stopped_at = travel + zero * t_rp + zero * 0.0 * t_s1 / 2 + const

    @staticmethod
    def _travel(v0, cap, reach, window: float, config: SafetyConfig) -> np.ndarray:
        """`person_travel` over `window` (near at NEAR_DISTANCE + NEAR_AHEAD), its cap and its
        reach (`bounded_travel`'s (cap − v0) / acceleration) already worked out."""
        if config.human_speed == HumanSpeed.CONSTANT:
            return cap * window
        acceleration = config.hand_acceleration
        rising = np.minimum(reach, window)
        travel = v0 * rising + acceleration * rising * rising / 2 + cap * (window - rising)
        return np.maximum(travel, 0.0)

    def scales(self, room, full: np.ndarray | None = None) -> np.ndarray:
        """`planned_scales` at `room`; `full`: where S_p(1) ≤ room, if the caller knows."""
        room = np.asarray(room, dtype=float)
        reaches, beyond = self.capped
        in_rising = reaches & (beyond | (self.rising_at > room))
        c0, c1, c2 = (
            np.where(in_rising, a, b) for a, b in zip(self.rising, self.at_cap, strict=True)
        )
        # Between full and blocked, c0 ≤ room on the piece chosen (the at-cap line is a tangent
        # under the convex rising piece), so each piece's larger root is the one sought.
        k, const, r1, r2 = len(c0), self.const, self.r1, self.r2
        if c0.ndim and room.shape == c0.shape == r1.shape:
            # Both in one call (the arithmetic is per entry: the same figures).
            both = entry_scales(
                np.concatenate([room, room]),
                np.concatenate([c0, np.full_like(c0, const)]),
                np.concatenate([c1, r1]),
                np.concatenate([c2, r2]),
            )
            scales = np.minimum(both[:k], both[k:])
        else:
            scales = np.minimum(entry_scales(room, c0, c1, c2), entry_scales(room, const, r1, r2))
        scales = np.minimum(np.maximum(scales - _ROOT_SLACK, 0.0), 1.0)
        if full is None:  # S_p(1) (`planned_distance`: v_r1 s t_rp = r1, v_r1 s² t_s1 / 2 = r2)
            v0, cap, reach, t_rp, t_s1, config = self._hand
            travel = self._travel(v0, cap, reach, t_rp + t_s1 * 1.0, config)
            full = travel + self.r1 + self.r2 + self.const <= room
        return np.where(full, 1.0, np.where(self.stopped_at > room, 0.0, scales))


def banded_scales(v_h, gap, v_r1, t_rp, t_s1, config: SafetyConfig, creep: bool, full=None):
    """Per pair, the plan's speed scale that keeps S_p(s) + `slow_band` (`planned_scales`);
    with `creep` (`BandCreep`), within the band at least `CREEP_SHARE` of the scale that keeps
    S_p(s) itself, up to `BAND_CREEP`. `full`: where S_p(1) ≤ gap − slow_band, if the caller
    knows (`planned_limit`: nowhere)."""
    plan = _PlannedScales(v_h, gap, v_r1, t_rp, t_s1, config)
    separated = plan.scales(np.asarray(gap) - config.slow_band, full)
    if creep and separated.min() < BAND_CREEP:
        within = plan.scales(gap)
        separated = np.maximum(separated, np.minimum(CREEP_SHARE * within, BAND_CREEP))
    return separated


def assess(
    envelope: RobotEnvelope | SeparationPipeline,
    q: np.ndarray,
    v: np.ndarray,
    body: BodySpheres,
    intent: MotionIntent,
    config: SafetyConfig,
    joint_acceleration: float,
    opening: float | None = None,
    sampling: float = 0.0,
    lag: float = 0.0,
    band_creep: bool = False,
) -> SeparationReading:
    """One step of the monitor (see the module docstring) without a diagram: the arm at
    measured `q`, `v` (UR3_JOINTS order), the gripper at the measured `opening` (None: not
    measured), the operator's `body`, and the controller's `intent`. The plan's speed keeps
    S_p with the reaction time lengthened by `sampling` [s], the station's safety function's
    period, so that the function, which judges a period late, need not stop it. Closer than
    S_p, where the plan only creeps toward the person as fast as lets it stop short of them,
    the arm may also go on for `lag` [s] at the speed it has before a limit set now slows it
    (`MONITOR_LAG`). With `band_creep` the plan creeps on within the slow band (`BandCreep`).
    `envelope`: the controller's model of the robot, or its side's `SeparationPipeline`; poses
    the envelope's own context (its only side effect)."""
    v = np.asarray(v, dtype=float)
    moving = bool(np.abs(v).max(initial=0.0) > config.moving_speed)
    commanded = np.asarray(intent.qdot, dtype=float) * intent.rate
    imposed = bool(np.abs(v - commanded).max(initial=0.0) > IMPOSED_SPEED)
    if len(body.radii) == 0:
        return SeparationReading(moving=moving, imposed=imposed)
    # The plan's velocities until a limit set now governs the arm (`MotionIntent.ahead`): the
    # fastest of them toward each sphere, and the fastest joint's stopping time.
    ahead = np.asarray(intent.velocities_ahead(), dtype=float)
    geometry = pipeline_of(envelope).pairs(q, opening, intent.carrying, body)
    speeds = geometry.robot_speeds(np.vstack([v, ahead]))
    v_r, v_r1 = np.maximum(0.0, speeds[0]), np.maximum(0.0, speeds[1:].max(axis=0))
    # Measured: the S_p the standard asks to keep.
    s_p = protective_separation(geometry, v_r, stopping_time(v, joint_acceleration), config)
    t_s1 = stopping_time(np.abs(ahead).max(axis=0), joint_acceleration)
    gap = geometry.gap
    limit = planned_limit(geometry, v_r1, t_s1, config, sampling, lag, band_creep)
    return SeparationReading(
        separation=float(gap.min()),
        margin=float((gap - s_p).min()),
        short=bool(((gap < s_p) & beyond_contact_speed(v_r, config.contact_speed, body)).any()),
        limit=limit,
        moving=moving,
        imposed=imposed,
        lost=body.lost_for is not None,
    )


def planned_limit(
    geometry: BodyPairs,
    v_r1: np.ndarray,
    t_s1: float,
    config: SafetyConfig,
    sampling: float = 0.0,
    lag: float = 0.0,
    band_creep: bool = False,
) -> float:
    """The plan's speed scale (`SeparationReading.limit`) beside the body of `geometry`, the
    plan moving toward each sphere at `v_r1` (m×n, at least 0) at full speed with stopping
    time `t_s1` (see `assess`): what the controller's monitor and its forecast monitor both
    decide by."""
    if not config.enabled:
        return 1.0
    gap, t_r, v_h = geometry.gap, config.reaction_time, geometry.person_speed()
    t_rp = t_r + sampling
    # Only a pair the plan at full speed would bring within S_p(1) + slow_band can limit it:
    # every other pair's scale is 1 (`planned_scales`), whatever its contact speed. The rest
    # are judged alone, each as it would be among all (the arithmetic is per pair); with none
    # (a third of the monitor's periods on row 5) the plan goes at full speed.
    # S_p(1) as `planned_distance` has it (v_r1 s t_rp and v_r1 s² t_s1 / 2 at s = 1).
    travel = person_travel(v_h, gap, t_rp + t_s1 * 1.0, config, NEAR_DISTANCE + NEAR_AHEAD)
    s_p1 = travel + v_r1 * t_rp + v_r1 * t_s1 / 2 + separation_constant(config)
    near = s_p1 > gap - config.slow_band
    if not near.any():
        return 1.0
    gap, v_h, v_r1 = gap[near], v_h[near], v_r1[near]
    touch = np.broadcast_to(touchable(geometry.body)[None, :], near.shape)[near]
    # Planned: the plan at scale s keeps S_p(s) + slow_band (none of them keeps S_p(1) +
    # slow_band, `near`: `full` nowhere), or moves no faster than the region's contact speed.
    separated = banded_scales(v_h, gap, v_r1, t_rp, t_s1, config, band_creep, full=False)
    contact = np.broadcast_to(contact_speeds(config.contact_speed, geometry.body), near.shape)
    slow = CONTACT_SHARE * contact[near] / np.maximum(v_r1, _SLOWEST)
    # ... and only as fast as lets it stop short of the person where they are now: power and
    # force limiting permits a person coming into the robot, not the robot driving into them.
    reaction = t_r + sampling + lag
    short_of = entry_scales(gap, separation_constant(config), v_r1 * reaction, v_r1 * t_s1 / 2)
    slow = np.where(touch, np.minimum(slow, short_of), 0.0)  # head: none
    limit = float(np.maximum(separated, np.minimum(slow, 1.0)).min())
    return 0.0 if limit < SLOWEST_SCALE else limit


def log_step(
    log: SafetyLog, reading: SeparationReading, intent: MotionIntent, period: float
) -> SafetyLog:
    """`log` with one more monitor period: the reading's figures, the time slowed or stopped
    while the plan moves the arm (`plan_moves`) at a rate below 1 or at 0, and the delay that
    monitoring added: (1 − rate) × period from the moment it limits the speed until the rate is
    back at 1 (the ramp back counts; a stop to turn, or the protective stop, does not); not
    the distances of a `lost` reading."""
    seen = not reading.lost
    log = replace(
        log,
        steps=log.steps + 1,
        min_separation=min(log.min_separation, reading.separation if seen else np.inf),
        body_contacts=log.body_contacts + int(seen and reading.separation <= 0.0),
    )
    if reading.moving and seen:
        short = int(reading.short)
        commanded = plan_moves(intent) and not reading.imposed
        log = replace(
            log,
            min_margin=min(log.min_margin, reading.margin),
            violations=log.violations + (short if commanded else 0),
            imposed=log.imposed + (0 if commanded else short),
        )
    if plan_moves(intent):
        limiting = log.limiting or reading.limit < 1.0 - 1e-9
        if limiting:
            log = replace(log, ssm_delay=log.ssm_delay + (1.0 - intent.rate) * period)
        limiting = limiting and not (reading.limit >= 1.0 - 1e-9 and intent.rate >= 1.0 - 1e-9)
        log = replace(log, limiting=limiting)
        if intent.rate <= 1e-9:
            log = replace(log, stopped_time=log.stopped_time + period)
        elif intent.rate < 1.0 - 1e-9:
            log = replace(log, slowed_time=log.slowed_time + period)
    return log


def plan_moves(intent: MotionIntent) -> bool:
    """Whether the plan has the arm moving at this point: `intent.moving`, or stopped (rate 0)
    where the plan's own velocity is not zero (held still for bolts, or between tasks, the
    plan's velocity is zero)."""
    return intent.moving or (
        intent.rate <= 1e-9 and float(np.abs(intent.qdot).max(initial=0.0)) > 1e-9
    )


@dataclass(frozen=True)
class BodyAge:
    """What the monitor allows for the tracked body's age (`sensors:`; the scenario's body
    sensor model, `hrc_drake.scenario.sensors.SensorModel`). A fresh reading's age (now minus
    `BodySpheres.stamp`) is added to the reaction time the plan keeps S_p with: the person
    moved meanwhile.

    Attributes:
        stale_after: a reading older than this [s] is no body seen: the plan stops until a
            fresh one comes (the tracker's period plus its latency bound).
    """

    stale_after: float = float("inf")


def reading_age(body: BodySpheres, now: float) -> float:
    """How old `body` is at `now` [s] (a reading without a stamp is current: 0)."""
    return 0.0 if body.stamp is None else max(0.0, now - body.stamp)


def stale_reading(body: BodySpheres, now: float, age: BodyAge) -> bool:
    """Whether `body`, read at `now`, is older than `age.stale_after`."""
    return reading_age(body, now) > age.stale_after + 1e-9


class ControllerSeparationMonitor(LeafSystem):
    """The controller's speed and separation monitor (see the module docstring).

    Input ports: `ur3.state_estimated` (12: q then v, UR3_JOINTS order), `operator.body`
    (BodySpheres), `intent` (MotionIntent), `rg2.state_measured` (2: opening [m] and its rate;
    optional: unconnected, the fingers count over their whole travel). Output ports:
    `speed_limit` (1) and `reading` (SeparationReading). The log is the abstract state updated
    every `period` (`ControllerSeparationMonitor.log(context)`). `envelope` replaces the model
    built from `design`: an envelope, or the controller's `SeparationPipeline`, which the
    forecast monitor shares (`pipeline`). `age`: what it allows for the body reading's age
    (default: an exact tracker); a stale reading stops the plan."""

    def __init__(
        self,
        design: CellDesign,
        config: SafetyConfig,
        joint_acceleration: float,
        period: float,
        envelope: RobotEnvelope | SeparationPipeline | None = None,
        age: BodyAge | None = None,
    ):
        super().__init__()
        self.pipeline = pipeline_of(envelope if envelope is not None else RobotEnvelope(design))
        self.envelope = self.pipeline.envelope
        self._config, self._acc, self._period = config, joint_acceleration, period
        self._age = age if age is not None else BodyAge()
        self._state_port = self.DeclareVectorInputPort("ur3.state_estimated", 2 * len(UR3_JOINTS))
        self._body_port = self.DeclareAbstractInputPort("operator.body", AbstractValue.Make(NOBODY))
        self._intent_port = self.DeclareAbstractInputPort(
            "intent", AbstractValue.Make(MotionIntent())
        )
        self._gripper_port = self.DeclareVectorInputPort("rg2.state_measured", 2)
        self._reading_port = self.DeclareAbstractOutputPort(
            "reading", lambda: AbstractValue.Make(SeparationReading()), self._calc_reading
        )
        self.DeclareVectorOutputPort("speed_limit", BasicVector(1), self._calc_limit)
        self._log_index = self.DeclareAbstractState(AbstractValue.Make(SafetyLog()))
        self._creep_index = self.DeclareAbstractState(AbstractValue.Make(BandCreep()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def log(self, context) -> SafetyLog:
        """The log in this system's context."""
        return context.get_abstract_state(self._log_index).get_value()

    def creep(self, context) -> BandCreep:
        """Whether the plan may creep on within the slow band, in this system's context."""
        return context.get_abstract_state(self._creep_index).get_value()

    def _calc_limit(self, context, output) -> None:
        output.SetFromVector([self._reading_port.Eval(context).limit])

    def _calc_reading(self, context, output) -> None:
        x = self._state_port.Eval(context)
        n = len(UR3_JOINTS)
        opening = None
        if self._gripper_port.HasValue(context):
            opening = float(self._gripper_port.Eval(context)[0])
        body = self._body_port.Eval(context)
        reading = assess(
            self.pipeline,
            x[:n],
            x[n:],
            body,
            self._intent_port.Eval(context),
            self._config,
            self._acc,
            opening,
            self._period + reading_age(body, context.get_time()),
            MONITOR_LAG * self._period,
            self.creep(context).on,
        )
        if stale_reading(body, context.get_time(), self._age):
            # No body seen: the person may be anywhere, so the plan stops (docs/hardware.md,
            # "Body tracker"); the station's safety function stays on its own sensor.
            reading = replace(reading, limit=0.0, stale=True)
        output.set_value(reading)

    def _update(self, context, state) -> None:
        reading = self._reading_port.Eval(context)
        intent = self._intent_port.Eval(context)
        log = log_step(self.log(context), reading, intent, self._period)
        state.get_mutable_abstract_state(self._log_index).set_value(log)
        body = self._body_port.Eval(context)
        creep = band_creep_step(self.creep(context), reading, intent, body, self._period)
        state.get_mutable_abstract_state(self._creep_index).set_value(creep)


__all__ = [
    "BAND_CREEP",
    "MONITOR_LAG",
    "SLOWEST_SCALE",
    "STAND_BEFORE_CREEP",
    "STILL_SPEED",
    "BandCreep",
    "BodyAge",
    "ControllerSeparationMonitor",
    "SafetyLog",
    "SeparationReading",
    "assess",
    "band_creep_step",
    "banded_scales",
    "log_step",
    "plan_moves",
    "planned_distance",
    "planned_limit",
    "planned_scales",
    "reading_age",
    "stale_reading",
]
