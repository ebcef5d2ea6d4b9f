"""The UR3's driver over RTDE, with SDU Robotics' `ur_rtde` library: `UR3_STATUS` from RTDE's
outputs, `UR3_COMMAND` into `servoJ` (docs/hardware.md, "UR3: RTDE").

`Ur3RtdeDriver` wraps one `rtde_receive.RTDEReceiveInterface` and one
`rtde_control.RTDEControlInterface` (passed in, so that tests give fakes; by default made for
`Ur3RtdeSettings.host`). `status(stamp)` is the arm's `lcmt_panda_status`, `command(message)`
servoes to a command's joint positions, and `Ur3Bridge(driver, lcm).run()`
serves both over LCM at the RTDE rate. What it guarantees:

- **The status** is the station's own (`ur3_status`, so the controller reads it as it reads the
  simulated station's): positions and velocities from `actual_q`/`actual_qd`, the desired
  ones from `target_q`/`target_qd`/`target_qdd`, `joint_torque_desired` from `target_moment`,
  NaN where the UR3 measures nothing (joint torques, external torques, the success rate),
  `robot_utime` from RTDE's `timestamp` and `robot_mode` carrying the safety mode
  (`station_safety_mode`: UR's RTDE safety mode, and any robot mode but RUNNING, as the
  station's `SafetyMode`).
- **A command is sent** as `servoJ(q, speed, acceleration, servo_time, lookahead_time, gain)`
  with its positions in `UR3_JOINTS` order (`ur3_command_values`), unless the robot is stopped
  by its safety system or not running: then nothing at all is sent to the controller.
- **A command too fast is refused**: against the previous command while servoing (their steps
  over their stamps' interval), against the measured position when servoing starts (over one
  period), no joint may move faster than `velocity_limits`. A refused command stops the arm
  (`servoStop`) and raises `Ur3CommandRefused`, which ends `Ur3Bridge.run`.
- **A stale command stops the arm**: when no new `UR3_COMMAND` (a later `utime`) has come for
  `stale_after` (3 periods + 50 ms: 74 ms on a CB3, 56 ms on an e-Series), `servoStop`.

Tested at the library boundary only (tests/test_ur3_rtde.py: the names and arities the driver
calls against the installed `ur_rtde`, the mapping, the refusals, with fake interfaces). It has
not met a real controller or URSim.
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable, Sequence
from datetime import timedelta
from threading import Event
from typing import Protocol

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status

from hrc_drake.cell.link.channels import COMMANDS, MEASUREMENTS
from hrc_drake.cell.link.lcm_messages import (
    N_JOINTS,
    lcmt_ur3_tcp_force,
    tcp_force_message,
    ur3_command_values,
    ur3_status,
    utime,
)
from hrc_drake.cell.ports import SafetyMode
from hrc_drake.drivers.settings import Ur3RtdeSettings
from hrc_drake.robot_names import UR3_JOINTS

COMMAND_CHANNEL = next(c.channel for c in COMMANDS if c.message is lcmt_panda_command)
STATUS_CHANNEL = next(c.channel for c in MEASUREMENTS if c.message is lcmt_panda_status)
TCP_FORCE_CHANNEL = next(c.channel for c in MEASUREMENTS if c.message is lcmt_ur3_tcp_force)


class UrSafetyMode(enum.IntEnum):
    """RTDE's `safety_mode` (Universal Robots' RTDE guide; `SafetyMode` in Universal_Robots'
    Client_Library, `ur/datatypes.h`)."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13


class UrRobotMode(enum.IntEnum):
    """RTDE's `robot_mode` (as `RTDEReceiveInterface.getRobotMode` documents it)."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


# The stops that last until someone acts (unlocks, releases an emergency stop, repairs) are the
# station's protective stop; those that end when an outside safeguard clears, its safeguard stop.
_SAFETY = {
    UrSafetyMode.NORMAL: SafetyMode.NORMAL,
    UrSafetyMode.REDUCED: SafetyMode.REDUCED,
    UrSafetyMode.SAFEGUARD_STOP: SafetyMode.SAFEGUARD_STOP,
    UrSafetyMode.AUTOMATIC_MODE_SAFEGUARD_STOP: SafetyMode.SAFEGUARD_STOP,
    UrSafetyMode.SYSTEM_THREE_POSITION_ENABLING_STOP: SafetyMode.SAFEGUARD_STOP,
}


def station_safety_mode(safety_mode: int, robot_mode: int) -> SafetyMode:
    """The station's `SafetyMode` of RTDE's `safety_mode` and `robot_mode` codes: normal,
    reduced and the safeguard stops as they are; every other safety mode (protective stop,
    recovery, emergency stops, violation, fault, an unknown code) a protective stop; and a
    robot that is not RUNNING (powered off, idle, booting...) with a normal or reduced safety
    mode a safeguard stop (*assumption*: held still from outside the controller, it resumes
    when the robot runs again)."""
    try:
        mode = _SAFETY.get(UrSafetyMode(safety_mode), SafetyMode.PROTECTIVE_STOP)
    except ValueError:
        mode = SafetyMode.PROTECTIVE_STOP
    if not mode.stopped and robot_mode != UrRobotMode.RUNNING:
        return SafetyMode.SAFEGUARD_STOP
    return mode


class ReceiveInterface(Protocol):
    """What the driver calls of `rtde_receive.RTDEReceiveInterface`."""

    def isConnected(self) -> bool: ...
    def getTimestamp(self) -> float: ...
    def getActualQ(self) -> list[float]: ...
    def getActualQd(self) -> list[float]: ...
    def getTargetQ(self) -> list[float]: ...
    def getTargetQd(self) -> list[float]: ...
    def getTargetQdd(self) -> list[float]: ...
    def getTargetMoment(self) -> list[float]: ...
    def getActualTCPForce(self) -> list[float]: ...
    def getSafetyMode(self) -> int: ...
    def getRobotMode(self) -> int: ...
    def disconnect(self) -> None: ...


class ControlInterface(Protocol):
    """What the driver calls of `rtde_control.RTDEControlInterface`."""

    def servoJ(self, q, speed, acceleration, time, lookahead_time, gain) -> bool: ...
    def servoStop(self, a: float = 10.0) -> bool: ...
    def initPeriod(self) -> timedelta: ...
    def waitPeriod(self, start: timedelta) -> None: ...
    def stopScript(self) -> None: ...
    def disconnect(self) -> None: ...


class Ur3DriverError(RuntimeError):
    """The UR3 cannot be driven (connection lost, `servoJ` not taken)."""


class Ur3ConnectionError(Ur3DriverError, ConnectionError):
    """No UR controller answered RTDE (or ur_rtde's control script) where the settings say."""


class Ur3CommandRefused(Ur3DriverError):
    """A command the driver will not send (too fast); the arm has been stopped."""


class CommandOutcome(enum.StrEnum):
    """What became of a command."""

    SENT = "sent"  # servoJ with its positions
    SAFETY_STOP = "safety stop"  # the robot is stopped or not running: nothing sent
    OUT_OF_ORDER = "out of order"  # older than one sent before: nothing sent
    STALE = "stale"  # no newer command within `stale_after`: stopped (servoStop) if servoing
    NONE = "none"  # no command yet


def _default_interfaces(settings: Ur3RtdeSettings):
    import rtde_control  # ur_rtde: the `hardware` extra
    import rtde_receive

    try:
        receive = rtde_receive.RTDEReceiveInterface(settings.host, settings.frequency)
    except RuntimeError as err:  # ur_rtde's one exception for a connection it could not make
        raise Ur3ConnectionError(
            f"no UR controller answered RTDE at {settings.where} ({err}): check that the UR3's "
            "controller is on, reachable from this host and not in local-only mode, and give "
            "its address"
        ) from err
    try:
        control = rtde_control.RTDEControlInterface(settings.host, settings.frequency)
    except RuntimeError as err:
        receive.disconnect()
        raise Ur3ConnectionError(
            f"the UR controller at {settings.host} answers RTDE but ur_rtde's control script "
            f"did not start ({err}): put the robot in remote control, powered on and released, "
            "with no other program running"
        ) from err
    return receive, control


class Ur3RtdeDriver:
    """The UR3 behind `UR3_STATUS` and `UR3_COMMAND`, over ur_rtde (the module's docstring
    says what it guarantees). `receive` and `control` default to ur_rtde's interfaces,
    connected to `settings.host` (which uploads and starts ur_rtde's control script)."""

    def __init__(
        self,
        settings: Ur3RtdeSettings,
        receive: ReceiveInterface | None = None,
        control: ControlInterface | None = None,
    ):
        if receive is None or control is None:
            receive, control = _default_interfaces(settings)
        self.settings = settings
        self._receive = receive
        self._control = control
        self._limits = np.array(settings.velocity_limits)
        self._sent: tuple[int, np.ndarray] | None = None  # while servoing: (utime, q) last sent

    @property
    def servoing(self) -> bool:
        """Whether the arm servoes to the commands (a command sent since the last stop)."""
        return self._sent is not None

    def _joints(self, values: Sequence[float], what: str) -> list[float]:
        values = [float(x) for x in values]
        if len(values) != N_JOINTS:
            raise Ur3DriverError(f"RTDE {what}: {len(values)} joints where {N_JOINTS} are expected")
        return values

    def safety_mode(self) -> SafetyMode:
        """The robot's safety mode as the station's (`station_safety_mode`)."""
        return station_safety_mode(self._receive.getSafetyMode(), self._receive.getRobotMode())

    def status(self, stamp: int) -> lcmt_panda_status:
        """The arm's `UR3_STATUS` stamped `stamp` [us, the host's clock] (the mapping of the
        module's docstring)."""
        if not self._receive.isConnected():
            raise Ur3DriverError(f"RTDE: the connection to {self.settings.host} is lost")
        receive = self._receive
        q = self._joints(receive.getActualQ(), "actual_q")
        qd = self._joints(receive.getActualQd(), "actual_qd")
        mode = self.safety_mode()
        message = ur3_status(stamp, q + qd, [float(mode.stopped)], [float(mode)])
        message.robot_utime = utime(receive.getTimestamp())
        message.joint_position_desired = self._joints(receive.getTargetQ(), "target_q")
        message.joint_velocity_desired = self._joints(receive.getTargetQd(), "target_qd")
        message.joint_acceleration_desired = self._joints(receive.getTargetQdd(), "target_qdd")
        message.joint_torque_desired = self._joints(receive.getTargetMoment(), "target_moment")
        return message

    def tcp_force(self, stamp: int) -> lcmt_ur3_tcp_force:
        """The wrist load's `UR3_TCP_FORCE` stamped `stamp` [us]: RTDE's `actual_TCP_force`
        (force, then moment; the arm's base frame; on an e-Series its flange sensor, on a CB3
        an estimate from the joint currents) as it comes. Its sign is UR's, which nobody here
        has checked against a real arm; the station's reads +z when a part is pushed up
        against the fingers (docs/hardware.md)."""
        values = self._receive.getActualTCPForce()
        if len(values) != 6:
            raise Ur3DriverError(f"RTDE actual_TCP_force: {len(values)} values, not 6")
        return tcp_force_message(stamp, values)

    def _too_fast(self, stamp: int, q: np.ndarray) -> str | None:
        """Why a command at `stamp` to `q` is too fast, or None."""
        if self._sent is not None:
            last_stamp, reference = self._sent
            dt = min((stamp - last_stamp) * 1e-6, self.settings.stale_after)
            against = "the previous command"
        else:
            reference = np.array(self._joints(self._receive.getActualQ(), "actual_q"))
            dt, against = self.settings.period, "the measured position"
        step = np.abs(q - reference)
        excess = step - self._limits * dt
        worst = int(np.argmax(excess))
        if excess[worst] <= 1e-9:
            return None
        return (
            f"UR3_COMMAND at utime {stamp}: {UR3_JOINTS[worst]} moves {step[worst]:.4f} rad "
            f"from {against} in {dt * 1e3:.1f} ms ({step[worst] / dt:.2f} rad/s), beyond its "
            f"limit of {self._limits[worst]:.2f} rad/s; the arm is stopped (servoStop)"
        )

    def command(self, message: lcmt_panda_command) -> CommandOutcome:
        """Servo to `message`'s joint positions (`servoJ`), unless the robot is stopped or not
        running (nothing sent: `SAFETY_STOP`) or the message is older than the last one sent
        (`OUT_OF_ORDER`). Raises `Ur3CommandRefused` after `servoStop` for a command too fast
        (see the module's docstring), `Ur3DriverError` when ur_rtde does not take `servoJ`."""
        if self.safety_mode().stopped:
            self._sent = None  # the safety system stopped the servo: start again from the arm
            return CommandOutcome.SAFETY_STOP
        stamp = int(message.utime)
        if self._sent is not None and stamp < self._sent[0]:
            return CommandOutcome.OUT_OF_ORDER
        q = ur3_command_values(message)[0]
        reason = self._too_fast(stamp, q)
        if reason is not None:
            self.stop()
            raise Ur3CommandRefused(reason)
        s = self.settings
        taken = self._control.servoJ(
            [float(x) for x in q],
            s.servo_speed,
            s.servo_acceleration,
            s.servo_time,
            s.lookahead_time,
            s.gain,
        )
        if not taken:
            self.stop()
            raise Ur3DriverError(f"ur_rtde did not take servoJ (its script runs on {s.host}?)")
        self._sent = (stamp, q)
        return CommandOutcome.SENT

    def follow(self, message: lcmt_panda_command | None, age: float) -> CommandOutcome:
        """One cycle's command: the newest received, `message` (None before the first), which
        came `age` seconds ago. In a safety stop nothing is sent (`SAFETY_STOP`); older than
        `stale_after`, the arm is stopped if it servoes (`STALE`); else `command(message)`."""
        if message is None:
            return CommandOutcome.NONE
        if self.safety_mode().stopped:
            self._sent = None  # nothing to send, not even servoStop: the robot stopped itself
            return CommandOutcome.SAFETY_STOP
        if age > self.settings.stale_after:
            self.stop()
            return CommandOutcome.STALE
        return self.command(message)

    def stop(self) -> None:
        """Stop servoing (`servoStop`), if the arm servoes."""
        if self._sent is not None:
            self._sent = None
            self._control.servoStop(self.settings.stop_deceleration)

    def init_period(self) -> timedelta:
        """The start of a control cycle (ur_rtde's `initPeriod`)."""
        return self._control.initPeriod()

    def wait_period(self, start: timedelta) -> None:
        """Wait for the end of the cycle that began at `start` (ur_rtde's `waitPeriod`)."""
        self._control.waitPeriod(start)

    def close(self) -> None:
        """Stop the arm, end ur_rtde's script on the controller and disconnect."""
        self.stop()
        self._control.stopScript()
        self._control.disconnect()
        self._receive.disconnect()


class Ur3Bridge:
    """The UR3 on `lcm` (a `pydrake.lcm.DrakeLcm`), subscribed to `UR3_COMMAND` from its
    construction: each `cycle()` publishes `UR3_STATUS` and `UR3_TCP_FORCE` stamped with
    `clock` (the host's wall clock by default, in microseconds since the epoch: the real-time
    link's shared clock, `hrc_drake.cell.link.realtime`), then follows the newest command
    received (the latest `utime`; `Ur3RtdeDriver.follow`: older than `stale_after`, the arm
    stops)."""

    def __init__(self, driver: Ur3RtdeDriver, lcm, clock: Callable[[], float] = time.time):
        self.driver, self._lcm, self._clock = driver, lcm, clock
        self._newest: lcmt_panda_command | None = None
        self._received_at = -math.inf
        self._error: Exception | None = None
        lcm.Subscribe(COMMAND_CHANNEL, self._receive)

    def _receive(self, data: bytes) -> None:
        # An LCM handler must not raise (it is called from C): keep the error for the cycle.
        try:
            message = lcmt_panda_command.decode(data)
        except Exception as err:  # any decode failure ends the loop
            self._error = err
            return
        if self._newest is None or message.utime > self._newest.utime:
            self._newest, self._received_at = message, self._clock()

    def cycle(self) -> CommandOutcome:
        """One RTDE period: take the commands received, publish the status, follow the newest
        command; raises `Ur3DriverError` for an undecodable command (and as `follow` does)."""
        self._lcm.HandleSubscriptions(0)
        if self._error is not None:
            raise Ur3DriverError(f"{COMMAND_CHANNEL}: {self._error}") from self._error
        now = self._clock()
        self._lcm.Publish(STATUS_CHANNEL, self.driver.status(utime(now)).encode())
        self._lcm.Publish(TCP_FORCE_CHANNEL, self.driver.tcp_force(utime(now)).encode())
        return self.driver.follow(self._newest, now - self._received_at)

    def run(self, cycles: int | None = None, stop: Event | None = None) -> None:
        """Run `cycles` cycles (None: until an error or `stop` is set), each paced by
        ur_rtde's `initPeriod`/`waitPeriod`; a refused command, a lost connection or an
        undecodable command ends it, raising the error; either way the arm is left stopped
        (`servoStop`). `stop` (a `threading.Event`) ends it from another thread."""
        count = 0
        try:
            while (cycles is None or count < cycles) and not (stop is not None and stop.is_set()):
                start = self.driver.init_period()
                self.cycle()
                self.driver.wait_period(start)
                count += 1
        finally:
            self.driver.stop()
