"""The scenario's `safety:` section: how the robot keeps clear of the operator — the controller's
separation monitor and predictive timing, the person's travel both it and the station's safety
function allow for, and the station's safety function itself (`docs/cell.md`). Apart from
`hrc_drake.scenario.schema`, which takes `SafetyConfig` as its `safety` field, for length only."""

from dataclasses import dataclass, field
from enum import StrEnum


class Separation(StrEnum):
    """`safety.separation`: how the robot keeps clear of the operator."""

    PREDICTIVE = "predictive"  # times its moves around the forecast body; monitoring underneath
    REACTIVE = "reactive"  # the separation monitor alone


class HumanSpeed(StrEnum):
    """`safety.human_speed`: how far the person can come while the robot reacts and stops."""

    TRACKED = "tracked"  # the tracked speed, bounded by what a hand can reach (an acceleration)
    CONSTANT = "constant"  # ISO 13855's 1.6 m/s (2.0 m/s within 0.5 m) throughout


class SafeguardReset(StrEnum):
    """`safety.function.safeguard_reset`: how a safeguard stop ends once its cause has cleared."""

    AUTO = "auto"  # by itself, after the restart delay
    MANUAL = "manual"  # at a reset (the unlock input, or the simulated operator)


class Timing(StrEnum):
    """`safety.timing`: how predictive separation times the plan around the forecast."""

    WAIT = "wait"  # a wait at each motion's start, then the plan at full speed
    PATH_TIME = "path_time"  # each motion's speed along its path (`motion.path_time`)


@dataclass
class SafetyFunctionConfig:
    """The station's separation safety function (`hrc_drake.cell.station.safety_function`): what a
    safety-rated scanner and the robot's safety controller would run, apart from the controller.

    Attributes:
        enabled: the station stops the arm itself when the separation falls short (off: the
            command reaches the arm as the controller gives it; the run's check still counts).
        resume_clearance: m beyond the S_p of a robot at rest at which a safeguard stop clears
            and the arm resumes by itself.
        reduced_band: m beyond S_p within which the safety mode reads `reduced`.
        unlock_delay: s after a protective stop's cause clears until the simulated operator
            presses unlock (negative: never); with the station's `safety.unlock` input
            connected (a pendant's button, `--live`), only that input unlocks.
        safeguard_reset: how a safeguard stop ends once clear: `auto` (by itself, as a UR's
            safeguard stop input without a reset input) or `manual` (at a reset: the unlock
            input, or the simulated operator `unlock_delay` s after it cleared).
    """

    enabled: bool = True
    resume_clearance: float = 0.05
    reduced_band: float = 0.15
    unlock_delay: float = 1.0
    safeguard_reset: str = SafeguardReset.AUTO.value


@dataclass
class LimitSetConfig:
    """One of the UR's safety limit sets (`safety.limits.normal`, `safety.limits.reduced`): the
    speeds its safety system allows, measured from the joint encoders.

    Attributes:
        tool_speed: m/s at the tool flange and at the TCP.
        elbow_speed: m/s at the elbow.
        momentum: kg m/s of the arm and its gripper.
    """

    tool_speed: float = 1.5
    elbow_speed: float = 1.5
    momentum: float = 25.0


@dataclass
class ReducedLimitSetConfig(LimitSetConfig):
    """The reduced limit set (`safety.limits.reduced`): ISO 10218-1's reduced speed, 0.25 m/s
    (`shared/reference/ur3-rg2.md`), at the tool; the elbow's is our choice, the same, and the
    momentum's too."""

    tool_speed: float = 0.25
    elbow_speed: float = 0.25
    momentum: float = 10.0


@dataclass
class TriggerPlaneConfig:
    """A UR's "trigger reduced mode" plane (`safety.limits.reduced_plane`): while the TCP lies
    on the side `normal` points to, the reduced limits bind.

    Attributes:
        point: [x, y, z] of a point of the plane in world [m].
        normal: [x, y, z], the plane's normal, toward its reduced side.
    """

    point: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    normal: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])


@dataclass
class RobotLimitsConfig:
    """The UR's own safety limits (`safety.limits`; `hrc_drake.cell.robot_limits`): the
    normal set, and the reduced set that binds in reduced mode (the safety sensor's warning
    field, `safety.function.reduced_band`, or the `sim.safety.reduced` input). Its path control
    slows a command that would break the set in force; a measured speed over a limit by more
    than `tolerance` for `detection_time` is a protective stop. UR's presets are not in the
    reference: the normal set (1.5 m/s, 25 kg m/s) and the reduced set's momentum (10 kg m/s) are
    our choice, above anything the cell's plans command, and a risk assessment sets both.

    Attributes:
        enabled: the station enforces the limits (off: neither the cap nor the stop).
        normal: the normal limit set (`LimitSetConfig`).
        reduced: the reduced limit set; no limit above the normal set's.
        tolerance: m/s a measured speed may exceed its limit by (a UR e-Series speed limit's
            tolerance, 50 mm/s: its user manual's table of safety functions; the momentum's
            is its 3 kg m/s).
        detection_time: s a limit stays broken before the stop (a UR CB3's worst-case
            detection time for the TCP speed, 250 ms; the e-Series figure is not in the
            reference).
        transition: s after reduced mode begins during which the stop still judges by the
            normal set, while the arm slows to the reduced one (our choice).
        reduced_plane: a plane past which the TCP puts the robot in reduced mode
            (`TriggerPlaneConfig`; none by default).
    """

    enabled: bool = True
    normal: LimitSetConfig = field(default_factory=LimitSetConfig)
    reduced: ReducedLimitSetConfig = field(default_factory=ReducedLimitSetConfig)
    tolerance: float = 0.05
    detection_time: float = 0.25
    transition: float = 0.5
    reduced_plane: TriggerPlaneConfig | None = None


@dataclass
class SensorUnitConfig:
    """One unit of the safety-rated sensor (`safety.sensor.units`): a 3D time-of-flight safety
    camera mounted over the desk. The field of view, reach, frame rate and response time are
    SICK safeVisionary2's (`shared/reference/safety-and-devices.md`).

    Attributes:
        name: the unit's name (a fault names it; the events say it).
        position: [x, y, z] of the unit in world [m] (the table's top is z = 0).
        target: [x, y, z] its optical axis points at [m].
        field_of_view: [wide, narrow] degrees; the wide angle lies level (swap them to mount
            the unit on its side).
        reach: m the unit measures to (safeVisionary2: 2 m, 4 m extended).
        frame_rate: frames per second [Hz].
        response_time: s from the scene to the unit's output, its frame period included; a
            frame older than this is no frame (a safeguard stop).
        detection: the detection capability [m]: anything this wide is seen (the twin spaces
            its rays for it at the monitored space's far end). 0.07 is our choice, under the
            person model's thinnest part (the forearm, 0.08 m); SICK states hand and arm
            resolutions whose figures the reference does not give.
    """

    name: str = "overhead"
    position: list[float] = field(default_factory=lambda: [0.40, 0.0, 2.4])
    target: list[float] = field(default_factory=lambda: [0.40, 0.0, 0.0])
    field_of_view: list[float] = field(default_factory=lambda: [68.0, 42.0])
    reach: float = 4.0
    frame_rate: float = 30.0
    response_time: float = 0.055
    detection: float = 0.07


def _default_units() -> list[SensorUnitConfig]:
    # Three units: one over the desk and one at each side looking under the arm, so that what
    # the arm hides from one another sees (our layout; `docs/cell.md`, "The safety sensor").
    side = {"position": [0.30, 1.10, 1.10], "target": [0.35, 0.0, 0.15]}
    return [
        SensorUnitConfig(),
        SensorUnitConfig(name="left", **{**side, "position": [0.30, -1.10, 1.10]}),
        SensorUnitConfig(name="right", **side),
    ]


@dataclass
class SafetySensorConfig:
    """The safety-rated sensor the station's safety function reads (`safety.sensor`;
    `hrc_drake.cell.station.safety_sensor`): volumetric, it sees occupied volume, not a person,
    and counts what no unit sees as occupied. The model assumes the function it feeds meets
    `performance_level` (ISO 13849-1): a claim for the real cell's assessor to verify, as one
    safeVisionary2 alone is PL c.

    Attributes:
        enabled: the safety function reads this sensor, and the controller plans by the
            function's settings (`hrc_drake.cell.ssm.planning_settings`); off (the default),
            the function reads the simulated body itself, exactly and at once, which no real
            device gives: the price of the sensor is in `docs/cell.md`, "The safety sensor".
        units: the mounted units (`SensorUnitConfig`).
        space: [[x, y, z], [x, y, z]], the monitored space's lower and upper corners [m].
        voxel: the edge of the monitored space's voxels [m].
        margin: m round the robot's shapes (posed from its encoders) within which unseen volume
            is the robot's (the depth's noise, the encoders', the shapes' chains of spheres):
            the function is blind there.
        head_above: m over the table above which seen volume may be a head (no contact
            permitted); below, the torso's limits (the standing operator's head is higher).
        performance_level: the performance level the safety function is taken to meet.
    """

    enabled: bool = False
    units: list[SensorUnitConfig] = field(default_factory=_default_units)
    space: list[list[float]] = field(
        default_factory=lambda: [[-0.30, -0.55, 0.0], [1.15, 0.55, 0.80]]
    )
    voxel: float = 0.05
    margin: float = 0.05
    head_above: float = 0.64
    performance_level: str = "d"

    @property
    def response_time(self) -> float:
        """The slowest unit's response time [s]: how late the sensor's reading may be."""
        return max(u.response_time for u in self.units)


@dataclass
class SafetyConfig:
    """Speed and separation monitoring (ISO/TS 15066 5.5.4): S_p = v_h (T_r + T_s) + v_r T_r +
    S_s + C + Z_d + Z_r, at every Supervisor update.

    Attributes:
        enabled: monitor the separation and scale the robot's speed (off: the robot ignores the
            operator's body, which is still drawn and measured).
        human_speed: how far the person can come while the robot reacts and stops (S_h), for
            the planning monitor and the station's safety function alike: `tracked` (from the
            body's tracked speed toward the robot, speeding up at most at `hand_acceleration`
            up to ISO 13855's 1.6 m/s, 2.0 m/s within 0.5 m; ISO/TS 15066 5.5.4.2.3 allows a
            monitored speed) or `constant` (those speeds throughout, as for a person whose
            speed is not monitored).
        hand_acceleration: m/s², the bound of `tracked` (the simulated hands reach 24-29 m/s²,
            `benchmarks/reports/safety_check.md`).
        contact_speed: m/s; closer than S_p the robot may still move toward the person this
            fast, as power and force limiting permits a contact (ISO/TS 15066 §5.5.5, Annex A),
            never faster than the body region permits (0.28 m/s at the chest, none at the head:
            `hrc_drake.cell.contact_limits`); 0.25 m/s is ISO 10218-1's reduced speed; 0:
            separation alone; at most 7.5 m/s, the fastest the UR3's joints move its TCP.
        reaction_time: T_r [s], the robot's reaction time (0.1 s is a common assumption).
        intrusion: C [m]; 0 when the distance is taken to the body itself.
        human_uncertainty: Z_d [m], the body's position uncertainty (a tracked hand).
        robot_uncertainty: Z_r [m]; 0 for the simulated robot.
        slow_band: m above S_p within which the robot already slows down.
        moving_speed: rad/s; a robot joint faster than this counts as moving (violations);
            below 2π, the UR3's fastest joint speed.
        separation: `predictive` (the robot times its moves around where it forecasts the
            operator's body, monitoring underneath) or `reactive` (monitoring alone).
        departure: m; the observed hand this far from the forecast makes the robot forecast
            again and re-time its moves.
        max_wait: the longest a move is held back for the operator [s].
        timing: with `predictive` separation, `wait` (a wait at each motion's start) or
            `path_time` (each motion timed along its path: slowed, stopped and going on;
            `hrc_drake.motion.path_time`).
        forecast_spread: how much of its timing spread the forecast keeps (1: all of it; 0: it
            takes the person's modelled timing as exact, the bound that a perfect forecast of a
            person who behaves as modelled would reach;
            `hrc_drake.cell.controller.forecast.OperatorForecast`).
        function: the station's safety function (`SafetyFunctionConfig`); the settings above
            but T_r, C, Z_d and Z_r, which it shares, are the controller's.
        sensor: the safety-rated sensor the function reads (`SafetySensorConfig`); with it,
            the function takes ISO 13855's constant speeds (it measures none) and adds the
            slowest unit's response time to T_r.
        limits: the UR's own safety limits the station enforces (`RobotLimitsConfig`).
    """

    enabled: bool = True
    human_speed: str = HumanSpeed.TRACKED.value
    hand_acceleration: float = 30.0
    contact_speed: float = 0.25
    reaction_time: float = 0.1
    intrusion: float = 0.0
    human_uncertainty: float = 0.05
    robot_uncertainty: float = 0.0
    slow_band: float = 0.05
    moving_speed: float = 0.01
    separation: str = Separation.PREDICTIVE.value
    departure: float = 0.15
    max_wait: float = 6.0
    timing: str = Timing.WAIT.value
    forecast_spread: float = 1.0
    function: SafetyFunctionConfig = field(default_factory=SafetyFunctionConfig)
    sensor: SafetySensorConfig = field(default_factory=SafetySensorConfig)
    limits: RobotLimitsConfig = field(default_factory=RobotLimitsConfig)


__all__ = [
    "HumanSpeed",
    "LimitSetConfig",
    "ReducedLimitSetConfig",
    "RobotLimitsConfig",
    "SafeguardReset",
    "SafetyConfig",
    "SafetyFunctionConfig",
    "SafetySensorConfig",
    "SensorUnitConfig",
    "Separation",
    "Timing",
    "TriggerPlaneConfig",
]
