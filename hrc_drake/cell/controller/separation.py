"""Speed and separation monitoring (ISO/TS 15066 §5.5.4) in the controller, from what a real cell
measures.

The monitor belongs to the controller. It reads what a real cell offers: the arm's measured joint
state (`ur3.state_estimated`), optionally the gripper's measured opening (`rg2.state_measured`),
the tracked operator body (`operator.body`, world-frame spheres with velocities), and what the
Supervisor is about to do (`intent`: the plan's joint velocities at full speed, the part it
carries). Nothing comes from the simulator's SceneGraph or plant state.

Like a real controller it has its own kinematic model of the robot (`RobotEnvelope`,
`hrc_drake.cell.controller.robot_envelope`): the UR3, the gripper and the part it carries as
convex primitives posed from the measured joint state, never farther from a point than the true
shapes.

Each step is one forward-kinematics pass (the measured q on the monitor's own context), the
distance from every body sphere to every robot shape at once in numpy (the distance of the
sphere's centre minus its radius; a chain of spheres is thinner than its capsule between spheres,
so the radius counts `1 + CHAIN_GAP` times), and for every such pair the robot's velocity toward
the sphere at the shape's nearest point, from its link's spatial velocity (the link's spatial
velocity Jacobian, from the posed joint axes of the serial arm, times the measured v and times
the plan's q̇ at full speed). Every pair is assessed, not only each sphere's nearest shape: a
farther shape moving fast toward the sphere can need more room. With them it evaluates the
protective separation distance

    S_p = v_h (T_r + T_s) + v_r T_r + S_s + C + Z_d + Z_r

(ISO/TS 15066:2016 §5.5.4.2; the worked example of Marvel & Norcross 2017, "Implementing speed
and separation monitoring in collaborative robot workcells", Robot. Comput.-Integr. Manuf. 44).
The stopping time and distance come from the arm's joint acceleration limit a (MotionOptions): the
robot stops along its path by scaling its trajectory's time, so every joint decelerates together
and the fastest one sets the time, T_s = max_j |q̇_j| / a; a point's speed then falls linearly to
zero, S_s = v_r T_s / 2.

`speed_limit` (the Supervisor's input) is the largest speed scale s ∈ [0, 1] of the plan at which
every pair keeps at least S_p(s) + `slow_band`, with the plan's own velocities scaled by s (S_p
is quadratic in s): 1 is full speed, 0 a stop. The monitor's update logs each period
(`SafetyLog`): least separation, least margin (separation − S_p with the measured velocities)
while the robot moves, violations (steps where the robot moved with separation < S_p under its
own command: its plan moving it, or stopping it from a move), steps moved closer than S_p by an
outside force (`imposed`: a standstill commanded, or a joint IMPOSED_SPEED faster than
commanded: the arm pushed; counted apart, never hidden), body contacts, and the time spent
slowed and stopped while the plan moves the arm.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.robot_envelope import RobotEnvelope, nearest_points, speeds_toward
from hrc_drake.cell.person import CHAIN_GAP
from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell_models import CellDesign
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.scenario.schema import SafetyConfig

# A joint this much faster than commanded is moved from outside [rad/s] (our choice: the
# servo tracks its command to a few hundredths of a rad/s; an 80 N·m push on the shoulder
# reaches this within one 20 ms period).
IMPOSED_SPEED = 0.3
_TINY = 1e-12  # keeps `allowed_scale`'s division finite where its root vanishes
# ISO 13855's approach speeds, which ISO/TS 15066 §5.5.4.2.3 takes for a person whose speed is
# not monitored (shared/reference/collaboration.md): 1.6 m/s, 2.0 m/s closer than 0.5 m. A
# tracked hand bounded by `SafetyConfig.hand_acceleration` speeds up to them, no further.
FAR_SPEED, NEAR_SPEED, NEAR_DISTANCE = 1.6, 2.0, 0.5  # m/s, m/s, m


@dataclass(frozen=True)
class SeparationReading:
    """One step's assessment.

    Attributes:
        separation: least distance robot–body [m] (inf: nothing measured).
        margin: least separation − S_p with the measured velocities [m].
        limit: the speed scale allowed (see the module docstring).
        moving: a robot joint moves faster than `SafetyConfig.moving_speed`.
        imposed: a joint moves faster than commanded by more than IMPOSED_SPEED: the arm is
            moved by an outside force (a push), not by its servo.
    """

    separation: float = float("inf")
    margin: float = float("inf")
    limit: float = 1.0
    moving: bool = False
    imposed: bool = False

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


def allowed_scale(gap, a0, a1, a2) -> float:
    """The largest s ∈ [0, 1] with a0 + a1 s + a2 s² ≤ gap for every entry (0 if none).

    Vectorised over the entries; the root is taken in the form 2 (g − a0) / (a1 + √(a1² +
    4 a2 (g − a0))), which is exact for a2 = 0 and free of cancellation for small a2."""
    gap, a0, a1, a2 = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (gap, a0, a1, a2))
    limiting = a0 + a1 + a2 > gap
    if not limiting.any():
        return 1.0
    g, c0, c1, c2 = gap[limiting], a0[limiting], a1[limiting], a2[limiting]
    room = g - c0
    if (room < 0.0).any():
        return 0.0
    root = c1 + np.sqrt(np.maximum(c1 * c1 + 4.0 * c2 * room, 0.0))
    return float(np.clip((2.0 * room / np.maximum(root, _TINY)).min(), 0.0, 1.0))


def bounded_travel(v0, window: float, acceleration: float, cap) -> np.ndarray:
    """The farthest [m] a hand moving toward the robot at `v0` [m/s] can travel in `window` s
    when it speeds up at most at `acceleration` [m/s²], up to `cap` [m/s] (a hand already faster
    keeps its speed). Vectorised over `v0` and `cap`."""
    v0 = np.asarray(v0, dtype=float)
    cap = np.maximum(cap, v0)
    rising = np.minimum((cap - v0) / acceleration, window)
    return v0 * rising + acceleration * rising * rising / 2 + cap * (window - rising)


def body_gaps(
    envelope: RobotEnvelope,
    q: np.ndarray,
    opening: float | None,
    carrying: str | None,
    body: BodySpheres,
):
    """(R_WB, p_WB, pairs, gap): the envelope posed at arm positions `q` and the gripper's
    measured `opening` (None: the fingers over their whole travel) with the part `carrying`,
    its nearest points to every body sphere, and each pair's gap, the distance less the sphere's
    radius counted `1 + CHAIN_GAP` times (a chain of spheres is thinner than its capsule)."""
    shapes = envelope.shapes(carrying, opening is not None)
    R_WB, p_WB = envelope.pose(np.asarray(q, dtype=float), opening)
    pairs = nearest_points(shapes, R_WB, p_WB, body.centres)
    return R_WB, p_WB, pairs, pairs.distance - body.radii[None, :] * (1.0 + CHAIN_GAP)


def _human_travel(v_h, gap, config: SafetyConfig, t_s: float, t_s1: float):
    """(S_h with the measured stopping time, the speed v such that v (T_r + T_s(s)) bounds
    S_h for every speed scale s of the plan): the tracked speed held (`hand_acceleration` 0),
    or bounded by what the hand can reach within the window (`bounded_travel`, capped at ISO
    13855's speeds); the bound for the plan takes its longest window, at s = 1."""
    t_r = config.reaction_time
    if not (config.track_human_speed and config.hand_acceleration > 0):
        return v_h * (t_r + t_s), v_h
    a = config.hand_acceleration
    cap = np.where(gap < NEAR_DISTANCE, NEAR_SPEED, FAR_SPEED)
    planned = np.minimum(np.maximum(cap, v_h), v_h + a * (t_r + t_s1))
    return bounded_travel(v_h, t_r + t_s, a, cap), planned


def assess(
    envelope: RobotEnvelope,
    q: np.ndarray,
    v: np.ndarray,
    body: BodySpheres,
    intent: MotionIntent,
    config: SafetyConfig,
    joint_acceleration: float,
    opening: float | None = None,
) -> SeparationReading:
    """One step of the monitor (see the module docstring) without a diagram: the arm at
    measured `q`, `v` (UR3_JOINTS order), the gripper at the measured `opening` (None: not
    measured), the operator's `body`, and the controller's `intent`. Poses `envelope`'s own
    context (its only side effect)."""
    v = np.asarray(v, dtype=float)
    moving = bool(np.abs(v).max(initial=0.0) > config.moving_speed)
    commanded = np.asarray(intent.qdot, dtype=float) * intent.rate
    imposed = bool(np.abs(v - commanded).max(initial=0.0) > IMPOSED_SPEED)
    if len(body.radii) == 0:
        return SeparationReading(moving=moving, imposed=imposed)
    qdot = np.asarray(intent.qdot, dtype=float)
    R_WB, p_WB, pairs, gap = body_gaps(envelope, q, opening, intent.carrying, body)
    speeds = speeds_toward(envelope.link_velocities(R_WB, p_WB, np.stack([v, qdot])), pairs)
    if config.track_human_speed:
        v_h = np.maximum(0.0, -np.einsum("nj,mnj->mn", body.velocities, pairs.direction))
    else:
        v_h = np.full(gap.shape, config.human_speed)
    v_r, v_r1 = np.maximum(0.0, speeds)
    const = config.intrusion + config.human_uncertainty + config.robot_uncertainty
    t_r = config.reaction_time
    # Measured: the S_p the standard asks to keep.
    t_s = np.abs(v).max(initial=0.0) / joint_acceleration
    t_s1 = np.abs(qdot).max(initial=0.0) / joint_acceleration
    s_h, v_plan = _human_travel(v_h, gap, config, t_s, t_s1)
    s_p = s_h + v_r * t_r + v_r * t_s / 2 + const
    # Planned at scale s: S_p(s) = a0 + a1 s + a2 s^2.
    a0, a1, a2 = v_plan * t_r + const, v_plan * t_s1 + v_r1 * t_r, v_r1 * t_s1 / 2
    limit = allowed_scale(gap - config.slow_band, a0, a1, a2) if config.enabled else 1.0
    return SeparationReading(
        separation=float(gap.min()),
        margin=float((gap - s_p).min()),
        limit=limit,
        moving=moving,
        imposed=imposed,
    )


def log_step(
    log: SafetyLog, reading: SeparationReading, intent: MotionIntent, period: float
) -> SafetyLog:
    """`log` with one more monitor period: the reading's figures, the time slowed or stopped
    while the plan moves the arm (`plan_moves`) at a rate below 1 or at 0, and the delay that
    monitoring added: (1 − rate) × period from the moment it limits the speed until the rate is
    back at 1 (the ramp back counts; a stop to turn, or the protective stop, does not)."""
    log = replace(
        log,
        steps=log.steps + 1,
        min_separation=min(log.min_separation, reading.separation),
        body_contacts=log.body_contacts + int(reading.separation <= 0.0),
    )
    if reading.moving:
        short = int(reading.margin < 0.0)
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


class ControllerSeparationMonitor(LeafSystem):
    """The controller's speed and separation monitor (see the module docstring).

    Input ports: `ur3.state_estimated` (12: q then v, UR3_JOINTS order), `operator.body`
    (BodySpheres), `intent` (MotionIntent), `rg2.state_measured` (2: opening [m] and its rate;
    optional: unconnected, the fingers count over their whole travel). Output ports:
    `speed_limit` (1) and `reading` (SeparationReading). The log is the abstract state updated
    every `period` (`ControllerSeparationMonitor.log(context)`). `envelope` replaces the model
    built from `design` (one per monitor)."""

    def __init__(
        self,
        design: CellDesign,
        config: SafetyConfig,
        joint_acceleration: float,
        period: float,
        envelope: RobotEnvelope | None = None,
    ):
        super().__init__()
        self.envelope = envelope if envelope is not None else RobotEnvelope(design)
        self._config, self._acc, self._period = config, joint_acceleration, period
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
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def log(self, context) -> SafetyLog:
        """The log in this system's context."""
        return context.get_abstract_state(self._log_index).get_value()

    def _calc_limit(self, context, output) -> None:
        output.SetFromVector([self._reading_port.Eval(context).limit])

    def _calc_reading(self, context, output) -> None:
        x = self._state_port.Eval(context)
        n = len(UR3_JOINTS)
        opening = None
        if self._gripper_port.HasValue(context):
            opening = float(self._gripper_port.Eval(context)[0])
        reading = assess(
            self.envelope,
            x[:n],
            x[n:],
            self._body_port.Eval(context),
            self._intent_port.Eval(context),
            self._config,
            self._acc,
            opening,
        )
        output.set_value(reading)

    def _update(self, context, state) -> None:
        log = log_step(
            self.log(context),
            self._reading_port.Eval(context),
            self._intent_port.Eval(context),
            self._period,
        )
        state.get_mutable_abstract_state(self._log_index).set_value(log)


__all__ = [
    "ControllerSeparationMonitor",
    "SafetyLog",
    "SeparationReading",
    "allowed_scale",
    "assess",
    "body_gaps",
    "bounded_travel",
    "log_step",
    "plan_moves",
]
