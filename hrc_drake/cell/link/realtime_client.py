"""The cell station over LCM in real time, the controller's side (the rules:
`hrc_drake.cell.link.realtime`; the station's side: `hrc_drake.cell.link.realtime_server`).

`make_realtime_station_interface(scenario, lcm, pace)` is, as the lockstep's
`make_cell_station_interface`, a diagram with the station's controller-facing ports, made of
Drake's LCM systems: an `LcmInterfaceSystem` that the simulator polls, an `LcmSubscriberSystem`
per measured channel feeding `RealtimeReadings` (the newest message of each, decoded to the
station's ports, with `ur3.target` and `link.stale` beside them), and a `MessageEncoder` and an
`LcmPublisherSystem` per command channel, publishing every controller period. Its
`RealtimeSession` says hello before the simulation starts (the scenario's identity and the
pace), waits for the station's first reading on every channel, hears the station's errors, and
ends the session for the station's report.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import (
    BasicVector,
    Diagram,
    DiagramBuilder,
    LeafSystem,
    ValueProducer,
)
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem

from hrc_drake.cell.link.channels import (
    COMMANDS,
    MEASUREMENTS,
    REPORT_CHANNEL,
    SIM_CONTACTS,
    Port,
    StationChannel,
)
from hrc_drake.cell.link.lcm_messages import N_JOINTS
from hrc_drake.cell.link.lockstep import (
    Inbox,
    LockstepTimeouts,
    StationLinkError,
    greet_station,
    request_report,
)
from hrc_drake.cell.link.realtime import (
    SILENCE,
    STAMPED_CHANNELS,
    LinkClock,
    MessageEncoder,
    RealtimeFigures,
    Staleness,
    UpdateClock,
    age,
    channel_latencies,
    channel_rates,
    judge,
    silent,
    wall_utime,
)
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.scenario.schema import Scenario


def restamp(reading, now: float, seconds_old: float, pace: float):
    """`reading` (`BodySpheres`, `CellConfiguration`) stamped at simulated time `now` less its
    age, `seconds_old` of wall time over the `pace`: when it was measured, on this side's
    clock."""
    return replace(reading, stamp=now - seconds_old * pace)


class RealtimeSession:
    """The session with one station over `lcm` in real time: the hello before the simulation,
    the station's errors during it, its report after it (`hrc_drake.cell.link.lockstep`'s
    protocol, step 0 and the end, with the pace in the hello)."""

    def __init__(
        self,
        lcm: DrakeLcm,
        channels: Sequence[StationChannel],
        pace: float,
        identity: ScenarioIdentity | None,
        timeouts: LockstepTimeouts,
    ):
        self.lcm, self.pace, self._identity, self._timeouts = lcm, pace, identity, timeouts
        self._inbox = Inbox(lcm, {c.channel: c for c in channels}, REPORT_CHANNEL)
        self.clock: UpdateClock | None = None  # the readings' (set when the interface is made)
        self.link_clock = LinkClock(pace)  # started as the simulation starts

    @property
    def url(self) -> str:
        """The LCM URL of the link."""
        return self.lcm.get_lcm_url()

    def greet(self) -> None:
        """Before the simulation starts: the hello (ScenarioMismatch if the station serves
        another scenario or runs the link otherwise; StationLinkError if none answers within
        `timeouts.start`), then the station's first message on every measured channel
        (StationLinkError naming those still missing after `SILENCE`)."""
        greet_station(self.lcm, self._inbox, self._identity, self._timeouts, self.pace)
        names = list(self._inbox.count)
        start = wall_utime()
        while True:
            self._inbox.raise_errors()
            missing = [n for n in names if self._inbox.count[n] == 0]
            if not missing:
                self.link_clock.start(0.0)  # the simulation starts now
                return
            if age(start, wall_utime()) > SILENCE:
                raise StationLinkError(
                    f"the cell station on {self.url} answered but sent nothing on "
                    f"{', '.join(missing)} for {SILENCE:g} s: is it a real-time station "
                    "(hrc-drake station --realtime)?"
                )
            self.lcm.HandleSubscriptions(20)

    def raise_errors(self) -> None:
        """StationLinkError with the station's own error, if it sent one."""
        self._inbox.raise_errors()

    def silent(self) -> tuple[str, float] | None:
        """The measured channel quiet longest and for how long [s], if for more than
        `SILENCE` (`silent`)."""
        return silent(self._inbox.arrived, time.monotonic())

    def end(self, timeout: float | None = None) -> dict:
        """Tell the station the run is over; its report (`request_report`)."""
        limit = self._timeouts.step if timeout is None else timeout
        return request_report(self.lcm, self._inbox, wall_utime(), limit)

    def figures(self) -> RealtimeFigures | None:
        """How the controller's updates kept their pace (None before two)."""
        return None if self.clock is None else self.clock.figures()


def command_encoder(channel: StationChannel, clock: LinkClock) -> MessageEncoder:
    """A command channel's message from the controller's ports (input ports named like the
    channel's), stamped with the wall-clock time its simulated instant stands for."""
    return MessageEncoder(
        channel.ports,
        channel.message,
        lambda clock, t, values: channel.encode(clock.stamp(t), *values),
        clock,
    )


class RealtimeReadings(LeafSystem):
    """The station's measurements as the newest messages have them (see the module docstring).

    Input ports: one per measured channel, named after it (the message its LcmSubscriberSystem
    keeps). Output ports: the channels' station ports (`ur3.state_estimated`, ...; the tracked
    body stamped with its age on this simulator's clock), `ur3.target` (6: the command the
    station's arm followed when measured, NaN from a station that does not say) and
    `link.stale` (1 while an arm or body reading is stale). Every `period` (with the
    Supervisor's update) it notes the wall time and the staleness in `clock`, and ends the run
    with StationLinkError when a channel has been silent for `SILENCE` or the station sent its
    error."""

    def __init__(
        self,
        channels: Sequence[StationChannel],
        rates: dict[str, float],
        period: float,
        session: RealtimeSession,
        latencies: dict[str, float] | None = None,
    ):
        super().__init__()
        self._rates, self._pace = rates, session.pace
        self._latencies = latencies or {}
        self._session = session
        self.updates = UpdateClock(period, session.pace)
        self._messages = {
            c.channel: self.DeclareAbstractInputPort(c.channel, AbstractValue.Make(c.message()))
            for c in channels
        }
        tickets = {c: {self.input_port_ticket(p.get_index())} for c, p in self._messages.items()}
        now = {self.time_ticket()}.union(*tickets.values())
        self._judged = self.DeclareCacheEntry(
            "judged",
            ValueProducer(
                allocate=lambda: AbstractValue.Make((0, Staleness())), calc=self._calc_judged
            ),
            prerequisites_of_calc=now,
        )
        self._decoded = {
            c.channel: self.DeclareCacheEntry(
                f"decoded {c.channel}",
                ValueProducer(
                    allocate=lambda: AbstractValue.Make(()),
                    calc=lambda context, value, c=c: value.set_value(
                        c.decode(self._messages[c.channel].Eval(context))
                    ),
                ),
                prerequisites_of_calc=tickets[c.channel],
            )
            for c in channels
        }
        for c in channels:
            for index, port in enumerate(c.ports):
                self._declare_output(c.channel, index, port, now)
        self.DeclareVectorOutputPort(
            "ur3.target", BasicVector(N_JOINTS), self._calc_target, prerequisites_of_calc=now
        )
        self.DeclareVectorOutputPort(
            "link.stale", BasicVector(1), self._calc_stale, prerequisites_of_calc=now
        )
        self.DeclarePeriodicPublishEvent(period, 0.0, self._watch)

    def _declare_output(self, channel: str, index: int, port: Port, deps: set) -> None:
        def value(context):
            value = self._decoded[channel].Eval(context)[index]
            if channel in STAMPED_CHANNELS:
                value = self._restamped(context, value, channel)
            return value

        port.declare_output(self, value, deps)

    def _stamps(self, context) -> dict[str, int]:
        return {c: p.Eval(context).utime for c, p in self._messages.items()}

    def _calc_judged(self, context, value) -> None:
        # One reading of the wall clock per simulated time: every reader at that time agrees.
        now = self._session.link_clock.now()
        judged = judge(self._stamps(context), now, self._rates, self._pace, self._latencies)
        value.set_value((now, judged))

    def _restamped(self, context, reading, channel: str):
        """`reading` (a body, a configuration) of `channel` stamped on this simulator's clock:
        now less its message's age, in simulated seconds (`restamp`)."""
        now = self._judged.Eval(context)[0]
        utime = self._messages[channel].Eval(context).utime
        return restamp(reading, context.get_time(), age(utime, now), self._pace)

    def _calc_target(self, context, output) -> None:
        message = self._messages["UR3_STATUS"].Eval(context)
        target = np.asarray(message.joint_position_desired, dtype=float)
        output.SetFromVector(target if target.shape == (N_JOINTS,) else np.full(N_JOINTS, np.nan))

    def _calc_stale(self, context, output) -> None:
        output.SetFromVector([1.0 if self._judged.Eval(context)[1].any else 0.0])

    def _watch(self, context) -> None:
        self._session.raise_errors()
        now, staleness = self._judged.Eval(context)
        gone = self._session.silent()
        t = context.get_time()
        if gone is not None:
            channel, old = gone
            raise StationLinkError(
                f"the cell station stopped publishing on {self._session.url}: nothing on "
                f"{channel} for {old:.1f} s (the limit {SILENCE:g} s) at t = {t:.2f} s (it died "
                "or was stopped)"
            )
        arm = age(self._messages["UR3_STATUS"].Eval(context).utime, now)
        self.updates.note(t, now / 1e6, staleness, arm)


@dataclass(frozen=True)
class RealtimeInterface:
    """A station's ports over the real-time link: the `diagram` (the ports of
    `make_cell_station_interface`, with `ur3.target` and `link.stale` beside them) and the
    `session` to greet the station with before simulating it and to end after."""

    diagram: Diagram
    session: RealtimeSession


def make_realtime_station_interface(
    scenario: Scenario,
    lcm: DrakeLcm,
    pace: float = 1.0,
    *,
    timeouts: LockstepTimeouts | None = None,
    sim_contacts: bool = False,
    identity: ScenarioIdentity | None = None,
) -> RealtimeInterface:
    """The station of `scenario` as seen over `lcm` in real time at `pace` (see the module
    docstring): the controller-facing ports of `make_cell_station`, same names and types, and
    `ur3.target` and `link.stale`; with `sim_contacts` also `sim.contacts`. Greet the station
    (`session.greet()`) before the simulation starts; `identity` (default: `scenario`'s) is
    told it, and a station that serves another scenario refused."""
    if identity is None:
        identity = ScenarioIdentity.of(scenario)
    timeouts = timeouts if timeouts is not None else LockstepTimeouts()
    measured = [*MEASUREMENTS, *([SIM_CONTACTS] if sim_contacts else [])]
    session = RealtimeSession(lcm, measured, pace, identity, timeouts)
    period = scenario.run.period
    builder = DiagramBuilder()
    bus = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    readings = builder.AddNamedSystem(
        "realtime_readings",
        RealtimeReadings(
            measured, channel_rates(scenario), period, session, channel_latencies(scenario)
        ),
    )
    session.clock = readings.updates
    for c in measured:
        subscriber = builder.AddNamedSystem(
            f"subscribe {c.channel}", LcmSubscriberSystem.Make(c.channel, c.message, bus)
        )
        builder.Connect(subscriber.get_output_port(), readings.GetInputPort(c.channel))
    for c in COMMANDS:
        encoder = command_encoder(c, session.link_clock)
        encoder = builder.AddNamedSystem(f"encode {c.channel}", encoder)
        publisher = builder.AddNamedSystem(
            f"publish {c.channel}",
            LcmPublisherSystem.Make(c.channel, c.message, bus, publish_period=period),
        )
        builder.Connect(encoder.get_output_port(), publisher.get_input_port())
        for p in c.ports:
            builder.ExportInput(encoder.GetInputPort(p.name), p.name)
    for index in range(readings.num_output_ports()):
        port = readings.get_output_port(index)
        builder.ExportOutput(port, port.get_name())
    diagram = builder.Build()
    diagram.set_name("cell_station_realtime_interface")
    return RealtimeInterface(diagram, session)


__all__ = [
    "RealtimeInterface",
    "RealtimeReadings",
    "RealtimeSession",
    "command_encoder",
    "make_realtime_station_interface",
    "restamp",
]
