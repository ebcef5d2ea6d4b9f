"""The drivers' settings, without Drake or the devices' libraries: the one statement of each
default, which the drivers (`hrc_drake.drivers.rg2_modbus`, `hrc_drake.drivers.ur3_rtde`) use
and the scenario's `drivers:` section (`hrc_drake.scenario.drivers`, read by the Drake-free
loader) takes its defaults from."""

from __future__ import annotations

from dataclasses import dataclass

from hrc_drake.robot_names import UR3_JOINTS, UR3_VELOCITY_LIMITS

# RTDE's rate on each controller generation [Hz] (Universal Robots' RTDE guide).
CB3_FREQUENCY = 125.0
E_SERIES_FREQUENCY = 500.0
RTDE_FREQUENCIES = {CB3_FREQUENCY: "CB3", E_SERIES_FREQUENCY: "e-Series"}
RTDE_PORT = 30004  # the controller's RTDE server


@dataclass(frozen=True)
class Rg2Settings:
    """Where the RG2's Compute Box is and how the driver talks to it: `host` and `port` of its
    Modbus TCP server, the gripper's `unit` id on it, the `poll_rate` of readings [Hz] (the
    Compute Box answers at 10-50 Hz, an *assumption*) and the `timeout` of each request [s]."""

    host: str
    port: int = 502
    unit: int = 65
    poll_rate: float = 25.0
    timeout: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.port < 65536:
            raise ValueError(f"RG2 port {self.port}: give a TCP port, 1-65535 (502 by default)")
        if not 0 <= self.unit <= 255:
            raise ValueError(f"RG2 unit {self.unit}: a Modbus unit id is 0-255 (65 by default)")
        if not (self.poll_rate > 0 and self.timeout > 0):
            raise ValueError(
                f"RG2 poll_rate {self.poll_rate} Hz and timeout {self.timeout} s: both must be "
                "positive"
            )

    @property
    def where(self) -> str:
        """host:port of the Compute Box."""
        return f"{self.host}:{self.port}"


@dataclass(frozen=True)
class Ur3RtdeSettings:
    """How the driver talks to one UR3. `frequency` is RTDE's rate [Hz] (500 on an e-Series,
    the cell's UR3e, by default; 125 on a CB3: `e_series(host)`, `cb3(host)`); `servo_time` is
    `servoJ`'s `time` [s], one period; `lookahead_time` [s] (0.03–0.2) and `gain` (100–2000)
    are `servoj`'s. The commands' joints may move at most at `velocity_limits` [rad/s] (the
    UR3's, `UR3_JOINTS` order).
    `servo_speed` and `servo_acceleration` fill `servoJ`'s speed and acceleration, which
    ur_rtde 1.6 does not use; `stop_deceleration` [m/s², the tool's] is `servoStop`'s."""

    host: str
    frequency: float = E_SERIES_FREQUENCY
    servo_time: float = 1 / E_SERIES_FREQUENCY
    lookahead_time: float = 0.1
    gain: float = 300.0
    velocity_limits: tuple[float, ...] = UR3_VELOCITY_LIMITS
    servo_speed: float = 0.5
    servo_acceleration: float = 0.5
    stop_deceleration: float = 10.0
    stale_periods: int = 3
    stale_margin: float = 0.050

    def __post_init__(self):
        if self.frequency <= 0 or self.servo_time <= 0:
            raise ValueError("frequency and servo_time must be positive")
        if not 0.03 <= self.lookahead_time <= 0.2:
            raise ValueError(f"lookahead_time {self.lookahead_time} s is not in [0.03, 0.2]")
        if not 100 <= self.gain <= 2000:
            raise ValueError(f"gain {self.gain} is not in [100, 2000]")
        joints = len(UR3_JOINTS)
        if len(self.velocity_limits) != joints or min(self.velocity_limits) <= 0:
            raise ValueError(f"velocity_limits: {joints} positive limits, one per joint")

    @classmethod
    def cb3(cls, host: str) -> Ur3RtdeSettings:
        """A CB3 controller: RTDE at 125 Hz."""
        return cls(host, frequency=CB3_FREQUENCY, servo_time=1 / CB3_FREQUENCY)

    @classmethod
    def e_series(cls, host: str) -> Ur3RtdeSettings:
        """An e-Series controller: RTDE at 500 Hz."""
        return cls(host, frequency=E_SERIES_FREQUENCY, servo_time=1 / E_SERIES_FREQUENCY)

    @property
    def period(self) -> float:
        """RTDE's period [s]."""
        return 1.0 / self.frequency

    @property
    def stale_after(self) -> float:
        """How long [s] the newest command may go without a newer one before the arm is
        stopped: `stale_periods` periods and `stale_margin`."""
        return self.stale_periods * self.period + self.stale_margin

    @property
    def where(self) -> str:
        """host:port of the controller's RTDE server."""
        return f"{self.host}:{RTDE_PORT}"


__all__ = [
    "CB3_FREQUENCY",
    "E_SERIES_FREQUENCY",
    "RTDE_FREQUENCIES",
    "RTDE_PORT",
    "Rg2Settings",
    "Ur3RtdeSettings",
]
