"""The real-time mode of the cell station over LCM: the rules both sides follow
(`hrc_drake.cell.link.realtime_client` the controller's side, `hrc_drake.cell.link.realtime_server`
the station's), beside the lockstep (`hrc_drake.cell.link.lockstep`), which stays the test
harness and the default.

In real time neither side waits for the other. The station's simulator and the controller's are
each paced to the wall clock (`Simulator.set_target_realtime_rate(pace)`); each side publishes
its channels at their own rates through Drake's LCM systems and reads the newest message of
each channel it hears, whatever came before.

**The clock.** Every message's `utime` is on the host's wall clock, microseconds since the
Unix epoch (`wall_utime`): the wall-clock time the sender's simulated instant stands for
(`LinkClock`: the wall time the sender started at, plus its simulated time since over the
pace), the instant the station measured (the tracked body: when its tracker took the reading,
`BodySpheres.stamp`; a camera's configuration: its newest frame whose verdicts it reports,
`CellConfiguration.stamp`) or the controller commanded; the reader puts those two back on its
own clock (now less their age, `STAMPED_CHANNELS`), so that the separation monitor allows for
the body's age and the controller waits for verdicts made after a part came to rest, as in one
process. A side on time stamps the wall clock now; a side that fell behind stamps late, and the
other side sees it as late. Both processes read the
same clock on one host (on two hosts, synchronised by PTP or NTP, their offset adds to every
age). The two simulators start within a message's trip of each other (the station starts
stepping at the controller's first command) and each keeps its own simulated time, which no
message carries.

**Commands on the station's own time.** The station takes a command at the plant step whose
instant the command's stamp stands for: a station on time takes the newest at once; one that
fell behind (its simulator stalled) walks from the command it held to the newest over their
stamps' interval, at its own simulated pace, so that the arm follows the commanded motion at
its commanded speed instead of jumping to where the controller has got to meanwhile.

**Rates.** `channel_rates`: the measured channels at their devices' rates, from the scenario's
`sensors:` section where it states one (`hrc_drake.scenario.sensors`: `ur3` 500 Hz, `rg2`
25 Hz, `body` 30 Hz, `wrench` 500 Hz under `realistic`; the camera of `configuration: camera` at its
own rate), else the same devices' figures stated once here
(`DEVICE_RATES`); the commands at the controller's rate (1 / `run.period`: 50 Hz).

**Staleness.** A reading is stale when it is older than `STALE_PERIODS` of its channel's
periods plus the latency bound its sensor model states (`channel_latencies`: a reading is
stamped when it was measured), in wall time (over the pace), plus `STALE_MARGIN`
(`stale_after`): under `ideal`, 56 ms for the arm at 500 Hz, 150 ms for the body at 30 Hz;
under `realistic`, the body's 100 ms of latency makes it 250 ms; the arm's command at 50 Hz
110 ms. What stops on it:

- a stale arm (`UR3_STATUS`) or body (`OPERATOR_BODY`) reading: the controller's next update
  (within one controller period) sets the Supervisor's speed scale to 0, so its plan
  decelerates along its path at the joint acceleration limit and the arm holds still
  (`link.stale`); the tracking check is skipped meanwhile (the reading says nothing of now).
  The plan resumes as a fresh reading comes.
- a stale arm command (`UR3_COMMAND`): the station's safety function brakes the arm at its next
  update (within one plant step) and holds it, a safeguard stop (`ur3.command_stale`,
  "no fresh command"); it resumes `RESTART_DELAY` after fresh commands come again, blending
  back to them.

**Silence.** A channel on which no message has come for `SILENCE` (2 s) ends the run on the
side that listens, with one line naming the channel and the URL (exit status 1): the
controller when the station died (within 2 s and one controller period of its last reading),
the station when the controller did (within 2 s and one plant step of its last command). A
side that only fell behind still speaks: its late readings stop the robot, as above, until it
catches up (a station that cannot keep real time on its machine leaves the robot stopped
most of the time; the run's `realtime` figures say so).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from hrc_drake.cell.link.channels import COMMANDS, SIM_CONTACTS, Port
from hrc_drake.scenario.schema import Scenario
from hrc_drake.scenario.sensors import PORTS, SensorModel, camera_model, sensor_models

STALE_PERIODS = 3  # periods of its channel a reading may be old before it is stale
STALE_MARGIN = 0.05  # s: a message's trip and the reader's own period, on top
SILENCE = 2.0  # s without a newer message on a channel: the other side is gone

# The devices' rates where the scenario's `sensors:` does not state them [Hz]: the UR3e's RTDE
# (an e-Series), the RG2 driver's Modbus poll (docs/hardware.md), a body tracker at about 30 Hz
# (issue 31); a camera's configuration and the operator's interface at a few tens of hertz (our
# choice). The simulation's touching pairs go at the controller's rate, as the run's collision
# watch reads them.
DEVICE_RATES = {
    "UR3_STATUS": 500.0,
    "UR3_TCP_FORCE": 500.0,
    "RG2_STATUS": 25.0,
    "CELL_CONFIGURATION": 20.0,
    "OPERATOR_BODY": 30.0,
    "HRI_INDICATION": 20.0,
}
# The measured channels whose rate a sensor model of `sensors:` states, by its key.
SENSOR_KEYS = {
    "UR3_STATUS": "ur3",
    "UR3_TCP_FORCE": "wrench",
    "RG2_STATUS": "rg2",
    "OPERATOR_BODY": "body",
}
# The readings whose staleness stops the robot: the arm's and the tracked body's.
WATCHED = ("UR3_STATUS", "OPERATOR_BODY")
# The readings stamped when they were measured rather than when published, whose reader
# restamps them on its own clock (`BodySpheres.stamp`, `CellConfiguration.stamp`).
STAMPED_CHANNELS = ("OPERATOR_BODY", "CELL_CONFIGURATION")
ARM_COMMAND = "UR3_COMMAND"


def wall_utime() -> int:
    """The shared clock: the host's wall clock [us since the Unix epoch]."""
    return time.time_ns() // 1000


class LinkClock:
    """The shared clock as one side's simulator stands for it: `stamp(t)` is the wall-clock
    time [us] its simulated instant `t` stands for, `w0 + (t - t0) / pace` from the instant
    `t0` it was started at, at wall time `w0` (`start`); before it is started, the wall clock
    itself. A side that falls behind the wall clock stamps its messages late, and the other
    side sees them so."""

    def __init__(self, pace: float, wall: Callable[[], int] = wall_utime):
        self.pace, self._wall = pace, wall
        self._origin: tuple[float, int] | None = None

    def start(self, t: float) -> None:
        """Simulated time `t` stands for now from here on."""
        self._origin = (t, self._wall())

    def stamp(self, t: float) -> int:
        """The wall-clock time [us] simulated time `t` stands for."""
        if self._origin is None:
            return self._wall()
        t0, w0 = self._origin
        return w0 + round((t - t0) / self.pace * 1e6)

    def now(self) -> int:
        """The wall clock now [us]."""
        return self._wall()


def _channel_models(scenario: Scenario) -> dict[str, SensorModel]:
    """The measured channels whose sensor model `scenario`'s `sensors:` states, with it."""
    models = sensor_models(scenario.sensors)
    found = {channel: models.get(PORTS[key]) for channel, key in SENSOR_KEYS.items()}
    return {channel: model for channel, model in found.items() if model is not None}


def channel_rates(scenario: Scenario) -> dict[str, float]:
    """Each channel's publishing rate [Hz] in `scenario` (see the module docstring)."""
    rates = dict(DEVICE_RATES)
    rates.update({channel: m.rate for channel, m in _channel_models(scenario).items()})
    camera = camera_model(scenario.sensors)
    if camera is not None:
        # A camera's poses come at its own few hertz; publishing faster would repeat them.
        rates["CELL_CONFIGURATION"] = camera.rate
    for channel in (*(c.channel for c in COMMANDS), SIM_CONTACTS.channel):
        rates[channel] = 1.0 / scenario.run.period
    return rates


def channel_latencies(scenario: Scenario) -> dict[str, float]:
    """Each measured channel's latency bound [s, simulated time] where a sensor model of
    `scenario` states one: a reading is stamped when it was measured, so it arrives that much
    old on time."""
    return {channel: m.latency_bound for channel, m in _channel_models(scenario).items()}


def stale_after(rate: float, pace: float, latency: float = 0.0) -> float:
    """The age [s, wall clock] past which a reading of a channel at `rate` [Hz, simulated
    time] and measured `latency` [s, simulated time] before it is sent is stale, both
    simulators paced at `pace`."""
    return (STALE_PERIODS / rate + latency) / pace + STALE_MARGIN


def age(stamp: int, now: int) -> float:
    """How old a message stamped `stamp` is at `now` [s] (both us on the shared clock; a clock
    that stepped back counts as 0)."""
    return max(0, now - stamp) / 1e6


@dataclass(frozen=True)
class Staleness:
    """One judgement of the watched readings: those stale, each (channel, age [s], bound [s])."""

    stale: tuple[tuple[str, float, float], ...] = ()

    @property
    def any(self) -> bool:
        """Whether a reading is stale (the robot stops)."""
        return bool(self.stale)

    def words(self) -> str:
        """The stale readings, for an event: "UR3_STATUS 0.081 s old (bound 0.074 s)"."""
        return ", ".join(f"{c} {a:.3f} s old (bound {b:.3f} s)" for c, a, b in self.stale)


def judge(
    stamps: dict[str, int],
    now: int,
    rates: dict[str, float],
    pace: float,
    latencies: dict[str, float] | None = None,
) -> Staleness:
    """The staleness of the `WATCHED` channels among `stamps` (each channel's newest `utime`)
    at `now`, with their `rates` and `latencies` (`channel_rates`, `channel_latencies`; see the
    module docstring)."""
    latencies = latencies or {}
    found = []
    for channel in WATCHED:
        if channel not in stamps:
            continue
        bound = stale_after(rates[channel], pace, latencies.get(channel, 0.0))
        old = age(stamps[channel], now)
        if old > bound:
            found.append((channel, old, bound))
    return Staleness(tuple(found))


def silent(arrived: dict[str, float], now: float) -> tuple[str, float] | None:
    """(channel, seconds) of the channel among `arrived` (each channel's newest arrival, on a
    clock that reads `now` now [s]) that has been quiet longest, if for more than `SILENCE`;
    None while every one speaks. Arrivals, not stamps: a side that fell behind still speaks,
    and its late readings stop the robot instead (`judge`)."""
    if not arrived:
        return None
    channel = min(arrived, key=arrived.__getitem__)
    quiet = now - arrived[channel]
    return (channel, quiet) if quiet > SILENCE else None


class MessageEncoder(LeafSystem):
    """A channel's message from ports, for an `LcmPublisherSystem`: input ports `ports`, output
    `message`, made by `make(clock, t, values)` with `t` the simulated time when its publisher
    publishes it and `values` the inputs' in `ports` order (`clock.stamp(t)`: its `utime`)."""

    def __init__(
        self,
        ports: Sequence[Port],
        message: type,
        make: Callable[[LinkClock, float, list], object],
        clock: LinkClock,
    ):
        super().__init__()
        self._make, self._clock = make, clock
        self._ports = [port.declare_input(self) for port in ports]
        self.DeclareAbstractOutputPort("message", lambda: AbstractValue.Make(message()), self._calc)

    def _calc(self, context, output) -> None:
        values = [p.Eval(context) for p in self._ports]
        output.set_value(self._make(self._clock, context.get_time(), values))


@dataclass(frozen=True)
class RealtimeFigures:
    """How a real-time run kept its pace (`simulate --json` `realtime`). Wall-clock figures
    of the controller's updates: their mean period, the jitter |period - target| (the target:
    `run.period` over the pace), the updates later than one target period after they were due
    (due: the first update's wall time plus the simulated time since over the pace), the pace
    achieved (simulated over wall time), the stops on stale readings, and how old the arm's
    reading was at the updates (its percentiles: the station's lag and the trip)."""

    pace: float
    updates: int
    period: float  # mean wall seconds between updates
    target_period: float
    jitter_p50: float
    jitter_p99: float
    jitter_max: float
    missed_deadlines: int
    max_lateness: float  # s: the latest update after it was due
    pace_achieved: float
    stale_stops: int = 0
    stale_time: float = 0.0  # s of simulated time stopped on stale readings
    stale_events: tuple[str, ...] = ()
    arm_age: tuple[float, float, float] = (0.0, 0.0, 0.0)  # p50, p99, max [s]

    def to_json(self) -> dict:
        """The JSON figures (seconds to the microsecond)."""

        def us(x: float) -> float:
            return round(x, 6)

        return {
            "pace": self.pace,
            "pace_achieved": round(self.pace_achieved, 4),
            "updates": self.updates,
            "period": us(self.period),
            "target_period": us(self.target_period),
            "jitter": {
                "p50": us(self.jitter_p50),
                "p99": us(self.jitter_p99),
                "max": us(self.jitter_max),
            },
            "missed_deadlines": self.missed_deadlines,
            "max_lateness": us(self.max_lateness),
            "stale_stops": self.stale_stops,
            "stale_time": round(self.stale_time, 3),
            "stale_events": list(self.stale_events),
            "arm_age": dict(zip(("p50", "p99", "max"), map(us, self.arm_age), strict=True)),
        }


@dataclass
class UpdateClock:
    """The wall-clock times of the controller's updates and its stops on stale readings, kept
    as the run goes (outside Drake's state: wall time is no part of a simulation's state)."""

    period: float
    pace: float
    times: list[float] = field(default_factory=list)
    walls: list[float] = field(default_factory=list)
    arm_ages: list[float] = field(default_factory=list)
    stale: Staleness = Staleness()
    stops: int = 0
    stale_since: float | None = None
    stale_time: float = 0.0
    events: list[str] = field(default_factory=list)

    def note(self, t: float, wall: float, staleness: Staleness, arm_age: float = 0.0) -> None:
        """The update at simulated time `t` ran at `wall` [s] with `staleness`, the arm's
        reading `arm_age` [s] old."""
        self.times.append(t)
        self.walls.append(wall)
        self.arm_ages.append(arm_age)
        if staleness.any and not self.stale.any:
            self.stops += 1
            self.stale_since = t
            self.events.append(f"{t:.2f}: {staleness.words()}: the robot stops on its path")
        elif self.stale.any and not staleness.any:
            self.stale_time += t - self.stale_since
            self.events.append(f"{t:.2f}: fresh readings: resumes")
        self.stale = staleness

    def figures(self) -> RealtimeFigures | None:
        """The figures so far (None before two updates)."""
        if len(self.walls) < 2:
            return None
        times, walls = np.array(self.times), np.array(self.walls)
        target = self.period / self.pace
        intervals = np.diff(walls)
        jitter = np.abs(intervals - target)
        late = walls - (walls[0] + (times - times[0]) / self.pace)
        stale_time = self.stale_time
        if self.stale.any:
            stale_time += times[-1] - self.stale_since
        return RealtimeFigures(
            pace=self.pace,
            updates=len(walls),
            period=float(intervals.mean()),
            target_period=target,
            jitter_p50=float(np.percentile(jitter, 50)),
            jitter_p99=float(np.percentile(jitter, 99)),
            jitter_max=float(jitter.max()),
            missed_deadlines=int((late > target + 1e-9).sum()),
            max_lateness=float(max(late.max(), 0.0)),
            pace_achieved=float((times[-1] - times[0]) / max(walls[-1] - walls[0], 1e-9)),
            stale_stops=self.stops,
            stale_time=stale_time,
            stale_events=tuple(self.events),
            arm_age=tuple(float(x) for x in np.percentile(self.arm_ages, [50, 99, 100])),
        )


__all__ = [
    "ARM_COMMAND",
    "DEVICE_RATES",
    "SILENCE",
    "STALE_MARGIN",
    "STALE_PERIODS",
    "STAMPED_CHANNELS",
    "WATCHED",
    "LinkClock",
    "MessageEncoder",
    "RealtimeFigures",
    "Staleness",
    "UpdateClock",
    "age",
    "channel_latencies",
    "channel_rates",
    "judge",
    "silent",
    "stale_after",
    "wall_utime",
]
