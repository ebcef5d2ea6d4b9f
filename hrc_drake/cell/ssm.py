"""Speed and separation monitoring's arithmetic (ISO/TS 15066:2016 §5.5.4), stated once for the
four that evaluate it through one pipeline (`hrc_drake.cell.separation_pipeline`): the
controller's planning monitor (`hrc_drake.cell.controller.separation`) and its forecast monitor,
the station's safety function (`hrc_drake.cell.station.safety_function`) and the run's own check
(`hrc_drake.cell.run.safety_check`). Each side has its own robot model (`RobotEnvelope`) and each
evaluator its own idea of the person's travel S_h; the protective separation distance around it
is the same:

    S_p = S_h + v_r T_r + S_s + C + Z_d + Z_r

(§5.5.4.2; the worked example of Marvel & Norcross 2017, "Implementing speed and separation
monitoring in collaborative robot workcells", Robot. Comput.-Integr. Manuf. 44). The robot stops
along its path by scaling its trajectory's time, so every joint decelerates together at the arm's
joint acceleration limit a and the fastest one sets the time, T_s = max_j |q̇_j| / a; a point's
speed then falls linearly to zero, S_s = v_r T_s / 2.

Separation and contact combine as ISO/TS 15066 allows: falling short of S_p counts only where
the robot moves toward the person faster than `safety.contact_speed` or than the body region's
permissible transient contact (`contact_speeds`, `hrc_drake.cell.contact_limits`; the default
0.25 m/s is ISO 10218-1's reduced speed, below every region's figure at any effective mass:
0.28 m/s for the chest, ≈1.3 m/s for the hand).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hrc_drake.cell.contact_limits import least_permissible_speeds, touchable
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.scenario.safety import HumanSpeed, SafetyConfig

# A joint this much faster than commanded is moved from outside [rad/s] (our choice: the
# servo tracks its command to a few hundredths of a rad/s; an 80 N·m push on the shoulder
# reaches this within one 20 ms period).
IMPOSED_SPEED = 0.3
_TINY = 1e-12  # keeps `allowed_scale`'s division finite where its root vanishes
# ISO 13855's approach speeds, which ISO/TS 15066 §5.5.4.2.3 takes for a person whose speed is
# not monitored (shared/reference/collaboration.md): 1.6 m/s, 2.0 m/s closer than 0.5 m. A
# tracked hand bounded by `SafetyConfig.hand_acceleration` speeds up to them, no further.
FAR_SPEED, NEAR_SPEED, NEAR_DISTANCE = 1.6, 2.0, 0.5  # m/s, m/s, m
# ISO 10218-1's reduced speed: the run's check counts apart the shortfalls where the robot
# moved toward the person faster than this (shared/reference/collaboration.md).
REDUCED_SPEED = 0.25  # m/s


def entry_scales(gap, a0, a1, a2) -> np.ndarray:
    """Per entry, the largest s ∈ [0, 1] with a0 + a1 s + a2 s² ≤ gap (0 if none).

    Vectorised over the entries; the larger root is taken in the form 2 (g − a0) / (a1 + √D),
    D = a1² + 4 a2 (g − a0), which is exact for a2 = 0 and free of cancellation for small a2.
    A negative a1 (a quadratic that dips first, a2 > 0; `planned_scales`) is allowed where
    a0 ≤ gap: there the root is (√D − a1) / (2 a2), the form free of cancellation for it."""
    # Broadcast by the arithmetic: np.broadcast_arrays took a third of a call's time.
    gap, a0, a1, a2 = (np.asarray(x, dtype=float) for x in (gap, a0, a1, a2))
    room = gap - a0
    disc = np.sqrt(np.maximum(a1 * a1 + 4.0 * a2 * np.maximum(room, 0.0), 0.0))
    root = np.where(
        a1 >= 0.0,
        2.0 * room / np.maximum(a1 + disc, _TINY),
        (disc - a1) / np.maximum(2.0 * a2, _TINY),
    )
    scales = np.minimum(np.maximum(root, 0.0), 1.0)
    return np.atleast_1d(np.where(a0 + a1 + a2 <= gap, 1.0, np.where(room < 0.0, 0.0, scales)))


def allowed_scale(gap, a0, a1, a2) -> float:
    """The largest s ∈ [0, 1] with a0 + a1 s + a2 s² ≤ gap for every entry (0 if none)."""
    return float(entry_scales(gap, a0, a1, a2).min(initial=1.0))


def bounded_travel(v0, window: float, acceleration: float, cap) -> np.ndarray:
    """The farthest [m] a hand moving toward the robot at `v0` [m/s] can travel in `window` s
    when it speeds up at most at `acceleration` [m/s²], up to `cap` [m/s] (a hand already faster
    keeps its speed). Vectorised over `v0` and `cap`."""
    v0 = np.asarray(v0, dtype=float)
    cap = np.maximum(cap, v0)
    rising = np.minimum((cap - v0) / acceleration, window)
    return v0 * rising + acceleration * rising * rising / 2 + cap * (window - rising)


def person_travel(
    v_toward, gap, window: float, config: SafetyConfig, near: float = NEAR_DISTANCE
) -> np.ndarray:
    """S_h [m] per pair: how far the person can come toward the robot in `window` s, as
    `safety.human_speed` says: `tracked`, from their tracked speed toward it `v_toward` [m/s]
    (signed: a hand moving away must turn first) speeding up at most at `hand_acceleration`
    up to ISO 13855's speeds; `constant`, those speeds throughout. The speed is 2.0 m/s where
    the `gap` is under `near` (ISO 13855's 0.5 m), else 1.6 m/s. Vectorised over the pairs."""
    cap = np.where(np.asarray(gap) < near, NEAR_SPEED, FAR_SPEED)
    if config.human_speed == HumanSpeed.CONSTANT:
        return cap * window
    travel = bounded_travel(v_toward, window, config.hand_acceleration, cap)
    return np.maximum(travel, 0.0)


def beyond_contact_speed(v_r, speed: float, body: BodySpheres):
    """Per (shape, sphere) pair, where the robot moves toward the person faster than `speed`
    [m/s] or than the sphere's body region permits (`contact_speeds`), or toward the head at
    all: where falling short of S_p is not a contact that power and force limiting permits
    (ISO/TS 15066 §5.5.5 with Annex A, which permits none with the face or skull,
    `touchable`). A speed of 0 is separation alone: every pair."""
    if speed <= 0.0:
        return np.ones(np.shape(v_r), dtype=bool)
    return (np.asarray(v_r) > contact_speeds(speed, body)[None, :]) | ~touchable(body)[None, :]


def contact_speeds(speed: float, body: BodySpheres) -> np.ndarray:
    """Per sphere of `body`, how fast [m/s] the robot may move toward it inside S_p:
    `speed` (`safety.contact_speed`), never above what Annex A permits its body region against
    a robot of any effective mass (`least_permissible_speeds`; 0 at the head)."""
    return np.minimum(speed, least_permissible_speeds(body))


def stopping_time(v: np.ndarray, joint_acceleration: float) -> float:
    """T_s [s]: the arm at joint velocities `v` [rad/s] stopping along its path, every joint
    decelerating together at `joint_acceleration` [rad/s²] (the fastest sets the time)."""
    return float(np.abs(np.asarray(v, dtype=float)).max(initial=0.0)) / joint_acceleration


def separation_constant(config: SafetyConfig) -> float:
    """C + Z_d + Z_r [m]: the intrusion distance and the position uncertainties."""
    return config.intrusion + config.human_uncertainty + config.robot_uncertainty


def protective_distance(s_h, v_r, t_s: float, config: SafetyConfig, sampling: float = 0.0):
    """S_p [m] from the person's travel `s_h` [m] and the robot's speed toward them `v_r`
    [m/s] with stopping time `t_s` [s]: S_h + v_r (T_r + `sampling`) + v_r T_s / 2 + C + Z_d +
    Z_r, the reaction lengthened by a sampling monitor's period."""
    reaction = config.reaction_time + sampling
    return s_h + v_r * reaction + v_r * t_s / 2 + separation_constant(config)


def function_settings(safety: SafetyConfig) -> SafetyConfig:
    """The settings the station's safety function keeps separation by: with the safety-rated
    sensor (`safety.sensor`), ISO 13855's constant speeds (a volumetric sensor measures no
    one's speed) and T_r lengthened by its slowest unit's response time; without it, `safety`
    as given."""
    sensor = safety.sensor
    if not sensor.enabled:
        return safety
    return replace(
        safety,
        human_speed=HumanSpeed.CONSTANT.value,
        reaction_time=safety.reaction_time + sensor.response_time,
    )


def planning_settings(safety: SafetyConfig) -> SafetyConfig:
    """The settings the controller plans and monitors by: the safety function's
    (`function_settings`), so that the function seldom has to stop what the controller
    commands. No margin is added for the sensor's reading: it gives the points its rays met,
    within a centimetre of the body (`hrc_drake.cell.volumetric.unexplained`)."""
    return function_settings(safety)


__all__ = [
    "FAR_SPEED",
    "IMPOSED_SPEED",
    "NEAR_DISTANCE",
    "NEAR_SPEED",
    "REDUCED_SPEED",
    "allowed_scale",
    "beyond_contact_speed",
    "bounded_travel",
    "contact_speeds",
    "entry_scales",
    "function_settings",
    "person_travel",
    "planning_settings",
    "protective_distance",
    "separation_constant",
    "stopping_time",
]
