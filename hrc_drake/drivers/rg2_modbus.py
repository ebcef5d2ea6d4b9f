"""The OnRobot RG2 over Modbus TCP (its Compute Box), and a bridge to the cell's LCM channels.

`Rg2Modbus` writes a target (opening, force) to the gripper's holding registers and reads its
width and status back; `Rg2LcmBridge` serves the station's RG2 channels with it: it takes
`RG2_COMMAND` and publishes `RG2_STATUS` at the driver's poll rate, stamped with the host's
clock. The register map and the units are docs/hardware.md's ("RG2: OnRobot Compute Box,
Modbus TCP"); the messages and their conversions are the station link's own
(`hrc_drake.cell.link.channels`), so the bridge serves exactly what the simulated station does.

Tested against a Modbus server on the loopback driven by the simulated gripper
(tests/test_rg2_modbus.py); it has not met a real Compute Box.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from pydrake.lcm import DrakeLcm
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from hrc_drake.cell.link.channels import COMMANDS, MEASUREMENTS, StationChannel
from hrc_drake.cell.link.lcm_messages import utime
from hrc_drake.cell.link.lcm_struct import LcmDecodeError
from hrc_drake.cell.scenario import DEFAULT_LCM_URL
from hrc_drake.drivers.settings import Rg2Settings
from hrc_drake.robot_models import RG2_MAX_FORCE, RG2_MAX_OPENING, RG2_MIN_FORCE

_log = logging.getLogger(__name__)

# Holding registers of the RG2 on its Compute Box (docs/hardware.md).
TARGET_FORCE = 0  # 1/10 N
TARGET_WIDTH = 1  # 1/10 mm, between the finger insides
CONTROL = 2  # GRIP, STOP or GRIP_WITH_OFFSET
ACTUAL_WIDTH = 267  # 1/10 mm, between the finger insides
STATUS = 268  # BUSY | GRIP_DETECTED | safety switches (bits 2-6)
GRIP, STOP, GRIP_WITH_OFFSET = 1, 8, 16
BUSY, GRIP_DETECTED = 0x1, 0x2

WIDTH_PER_METRE = 10_000  # register counts (1/10 mm) per metre
FORCE_PER_NEWTON = 10  # register counts (1/10 N) per newton
# The gripper takes a new target only when it is not busy, and the controller's opening is a
# ramp (a new sample every control period): a target goes out only when it differs from the
# last one sent by more than 1 mm, or its force changed (docs/hardware.md's rule, an
# *assumption* not checked on a real RG2). The ramp's end also goes out once it is commanded
# twice in a row, so that the fingers settle on the commanded width, not up to 1 mm from it.
RESEND_WIDTH = 10  # register counts: 1 mm
_MAX_HANDLED = 100  # LCM batches handled at one poll (DrakeLcm keeps a channel's newest)


class Rg2Error(RuntimeError):
    """The RG2 did not answer as it should (an exception response, or no answer)."""


class Rg2ConnectionError(Rg2Error, ConnectionError):
    """No Modbus TCP server (or no RG2 behind it) where the settings say."""


@dataclass(frozen=True)
class Rg2Target:
    """A target as the registers hold it: `force` [1/10 N] and `width` [1/10 mm]."""

    force: int
    width: int


def rg2_target(opening: float, force: float) -> Rg2Target:
    """The registers of a target `opening` between the finger insides [m] and gripping `force`
    [N]; ValueError for a value outside the RG2's stroke (0 to RG2_MAX_OPENING) or force range
    (RG2_MIN_FORCE to RG2_MAX_FORCE), checked on the rounded register values (so that 0.110
    m read back through floating point is still in range)."""
    if not (math.isfinite(opening) and math.isfinite(force)):
        raise ValueError(f"RG2 target opening {opening} m, force {force} N: not a number")
    width = round(opening * WIDTH_PER_METRE)
    counts = round(force * FORCE_PER_NEWTON)
    if not 0 <= width <= round(RG2_MAX_OPENING * WIDTH_PER_METRE):
        raise ValueError(
            f"RG2 target opening {opening} m is outside its stroke, 0 to {RG2_MAX_OPENING} m "
            "between the finger insides"
        )
    if not RG2_MIN_FORCE * FORCE_PER_NEWTON <= counts <= RG2_MAX_FORCE * FORCE_PER_NEWTON:
        raise ValueError(
            f"RG2 target force {force} N is outside its range, {RG2_MIN_FORCE} to {RG2_MAX_FORCE} N"
        )
    return Rg2Target(force=counts, width=width)


@dataclass(frozen=True)
class Rg2Reading:
    """What the RG2 reports: the `opening` between the finger insides [m], its `opening_rate`
    [m/s] (from this reading and the one before), `grip_detected` (the fingers stopped on an
    object before the target), `busy` (moving), and the host's clock at the reading [s, epoch]."""

    time: float
    opening: float
    opening_rate: float
    grip_detected: bool
    busy: bool


class Rg2Modbus:
    """The RG2 through its Compute Box's Modbus TCP server: `connect()`, `command(opening,
    force)`, `read()`, `close()` (or use it as a context manager). Not thread-safe: one thread
    (the bridge's) talks to it. `clock` gives the readings' time [s] (the host's clock)."""

    def __init__(self, settings: Rg2Settings, clock: Callable[[], float] = time.time):
        self.settings = settings
        self._clock = clock
        self._client: ModbusTcpClient | None = None
        self._sent: Rg2Target | None = None
        self._requested: Rg2Target | None = None
        self._last: Rg2Reading | None = None

    def __enter__(self) -> Rg2Modbus:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def connect(self) -> Rg2Reading:
        """Connect, and read the gripper once to know it answers; its first reading.
        Rg2ConnectionError naming host:port and what to check when nothing answers."""
        s = self.settings
        self.close()
        client = ModbusTcpClient(s.host, port=s.port, timeout=s.timeout, retries=0)
        if not client.connect():
            raise Rg2ConnectionError(
                f"no Modbus TCP server answered at {s.where} within {s.timeout} s: check that "
                "the RG2's Compute Box is on and reachable from this host, and give its address "
                "and port (Modbus TCP, 502 by default)"
            )
        self._client = client
        try:
            return self.read()
        except Rg2Error as err:
            self.close()
            raise Rg2ConnectionError(
                f"the Modbus TCP server at {s.where} does not serve an RG2 as unit {s.unit} "
                f"({err}): check the unit id (65 on a Compute Box)"
            ) from err

    def close(self) -> None:
        """Close the connection. A driver connected again sends its next target whatever it
        was (the gripper may have been restarted meanwhile)."""
        if self._client is not None:
            self._client.close()
        self._client = None
        self._last = self._sent = self._requested = None

    def command(self, opening: float, force: float) -> bool:
        """Take a target `opening` between the finger insides [m] and gripping `force` [N] and
        write it (registers 0-2: force, width, grip) when it is due (RESEND_WIDTH's rule);
        whether it was written. ValueError, and nothing sent, for a target the RG2 cannot take."""
        target = rg2_target(opening, force)
        held = target == self._requested
        self._requested = target
        last = self._sent
        due = (
            last is None
            or target.force != last.force
            or abs(target.width - last.width) > RESEND_WIDTH
            or (held and target.width != last.width)
        )
        if not due:
            return False
        self._request(
            f"write target registers {TARGET_FORCE}-{CONTROL}",
            lambda c: c.write_registers(
                TARGET_FORCE, [target.force, target.width, GRIP], device_id=self.settings.unit
            ),
        )
        self._sent = target
        return True

    @property
    def sent(self) -> Rg2Target | None:
        """The last target written (None: none yet)."""
        return self._sent

    def read(self) -> Rg2Reading:
        """Read the width and status registers (267-268) and difference the width against the
        previous reading for its rate (0 for the first)."""
        response = self._request(
            f"read registers {ACTUAL_WIDTH}-{STATUS}",
            lambda c: c.read_holding_registers(ACTUAL_WIDTH, count=2, device_id=self.settings.unit),
        )
        width, status = response.registers[:2]
        now, opening = self._clock(), width / WIDTH_PER_METRE
        last = self._last
        rate = 0.0
        if last is not None and now > last.time:
            rate = (opening - last.opening) / (now - last.time)
        reading = Rg2Reading(
            time=now,
            opening=opening,
            opening_rate=rate,
            grip_detected=bool(status & GRIP_DETECTED),
            busy=bool(status & BUSY),
        )
        self._last = reading
        return reading

    def _request(self, what: str, call: Callable[[ModbusTcpClient], object]):
        s = self.settings
        if self._client is None:
            raise Rg2Error(f"RG2 at {s.where}: not connected; call connect() first")
        try:
            response = call(self._client)
        except ModbusException as err:
            raise Rg2Error(f"RG2 at {s.where}, unit {s.unit}: {what}: {err}") from err
        if response.isError():
            raise Rg2Error(f"RG2 at {s.where}, unit {s.unit}: {what}: answered {response}")
        return response


def _channel(channels: tuple[StationChannel, ...], name: str) -> StationChannel:
    return next(c for c in channels if c.channel == name)


class Rg2LcmBridge:
    """Serves the station's RG2 channels with a real gripper: the newest `RG2_COMMAND`
    received goes to the driver at each poll, and each reading is published as `RG2_STATUS`
    stamped with the host's clock. A command the RG2 cannot take (or that cannot be read) is
    refused with a warning and counted in `refused`; the gripper keeps its last target."""

    def __init__(self, driver: Rg2Modbus, lcm: DrakeLcm):
        self.driver = driver
        self._lcm = lcm
        self._command = _channel(COMMANDS, "RG2_COMMAND")
        self._status = _channel(MEASUREMENTS, "RG2_STATUS")
        self._newest: bytes | None = None
        self.commands = 0  # commands taken
        self.refused: list[str] = []  # why the refused ones were
        self.published = 0
        lcm.Subscribe(self._command.channel, self._keep)

    def _keep(self, data: bytes) -> None:
        self._newest = data  # only the newest counts; decoded at the poll (handlers never throw)

    def step(self) -> Rg2Reading:
        """One poll: the newest command received since the last poll to the driver, then a
        reading published as `RG2_STATUS`."""
        # Without waiting: pydrake's HandleSubscriptions holds the GIL while it waits, which
        # would stall every other thread of the process.
        for _ in range(_MAX_HANDLED):
            if self._lcm.HandleSubscriptions(0) == 0:
                break
        data, self._newest = self._newest, None
        if data is not None:
            self._take(data)
        reading = self.driver.read()
        message = self._status.encode(
            utime(reading.time),
            [reading.opening, reading.opening_rate],
            [1.0 if reading.grip_detected else 0.0],
        )
        self._lcm.Publish(self._status.channel, message.encode())
        self.published += 1
        return reading

    def _take(self, data: bytes) -> None:
        try:
            opening, force = self._command.decode(self._command.message.decode(data))
            self.driver.command(float(opening[0]), float(force[0]))
        except (LcmDecodeError, ValueError) as err:
            self.refused.append(str(err))
            _log.warning("%s refused: %s", self._command.channel, err)
        else:
            self.commands += 1

    def run(self, stop: threading.Event) -> None:
        """Poll at the driver's rate until `stop` is set (a late poll is made at once and the
        schedule goes on from it: missed polls are not made up)."""
        period = 1.0 / self.driver.settings.poll_rate
        due = time.monotonic()
        while not stop.is_set():
            self.step()
            due = max(due + period, time.monotonic())
            stop.wait(due - time.monotonic())


def main(argv: list[str] | None = None) -> int:
    """`python -m hrc_drake.drivers.rg2_modbus --host ADDRESS`: serve the RG2's LCM channels
    with the real gripper until Ctrl-C; exit status 1 with one line if it cannot connect."""
    parser = argparse.ArgumentParser(
        prog="python -m hrc_drake.drivers.rg2_modbus",
        description="Serve RG2_COMMAND and RG2_STATUS on LCM with an RG2 over Modbus TCP.",
    )
    d = Rg2Settings("")  # the defaults, stated once
    parser.add_argument("--host", required=True, help="the Compute Box's address")
    parser.add_argument("--port", type=int, default=d.port, help=f"its Modbus TCP port ({d.port})")
    parser.add_argument("--unit", type=int, default=d.unit, help=f"the RG2's unit id ({d.unit})")
    parser.add_argument(
        "--poll-rate",
        type=float,
        default=d.poll_rate,
        help=f"readings per second ({d.poll_rate:g})",
    )
    parser.add_argument(
        "--timeout", type=float, default=d.timeout, help=f"per request [s] ({d.timeout:g})"
    )
    parser.add_argument("--lcm", default=DEFAULT_LCM_URL, help=f"LCM URL ({DEFAULT_LCM_URL})")
    args = parser.parse_args(argv)
    try:
        settings = Rg2Settings(args.host, args.port, args.unit, args.poll_rate, args.timeout)
    except ValueError as err:
        parser.error(str(err))
    driver = Rg2Modbus(settings)
    try:
        driver.connect()
    except Rg2ConnectionError as err:
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 1
    bridge = Rg2LcmBridge(driver, DrakeLcm(args.lcm))
    print(
        f"RG2 at {settings.where} (unit {settings.unit}): serving RG2_COMMAND and RG2_STATUS "
        f"on {args.lcm} at {settings.poll_rate:g} Hz; Ctrl-C stops",
        flush=True,
    )
    try:
        bridge.run(threading.Event())
    except KeyboardInterrupt:
        pass
    except Rg2Error as err:
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 1
    finally:
        driver.close()
    return 0


__all__ = [
    "Rg2ConnectionError",
    "Rg2Error",
    "Rg2LcmBridge",
    "Rg2Modbus",
    "Rg2Reading",
    "Rg2Settings",
    "Rg2Target",
    "rg2_target",
]

if __name__ == "__main__":
    sys.exit(main())
