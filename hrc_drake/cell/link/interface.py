"""The cell station over LCM, the controller's side: the controller in one process, the station
in another (`hrc_drake.cell.link.station_server`).

`make_cell_station_interface(scenario, lcm)` is, like Drake's `MakeHardwareStationInterface`, a
diagram with the station's controller-facing ports (`docs/station.md`): it publishes what the
controller commands and gives back what the station measured, over LCM (`lcm_messages`), in the
lockstep of `hrc_drake.cell.link.lockstep`. `end_station_session` ends its session and returns
the station's report.
"""

from __future__ import annotations

import time

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import (
    Context,
    Diagram,
    DiagramBuilder,
    EventStatus,
    LeafSystem,
)

from hrc_drake.cell.link.channels import (
    COMMANDS,
    MEASUREMENTS,
    PRE_SUFFIX,
    REPORT_CHANNEL,
    SIM_CONTACTS,
    Port,
    StationChannel,
)
from hrc_drake.cell.link.lcm_messages import utime
from hrc_drake.cell.link.lockstep import (
    Inbox,
    LockstepTimeouts,
    StationLinkError,
    exchange_period,
    greet_station,
    no_station,
    publish,
    request_report,
)
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.scenario.schema import Scenario


def _step_of(t: float, period: float) -> int:
    """The exchange at or just before time `t` (events fall on multiples of `period`)."""
    return int(np.floor(t / period + 1e-6))


class StationClient(LeafSystem):
    """The controller's side of the lockstep (`hrc_drake.cell.link.lockstep`): input ports are the
    station's command ports, output ports its measured ports (and, with `sim_contacts`, the
    simulation-only `sim.contacts`). One client serves one session with one station; it tells
    the station `identity`, the scenario the controller runs, before the first exchange."""

    def __init__(
        self,
        lcm: DrakeLcm,
        period: float,
        timeouts: LockstepTimeouts | None = None,
        sim_contacts: bool = False,
        identity: ScenarioIdentity | None = None,
    ):
        super().__init__()
        self._lcm, self._period = lcm, period
        self._identity, self._greeted = identity, False
        self._timeouts = timeouts if timeouts is not None else LockstepTimeouts()
        self._measured = [*MEASUREMENTS, *([SIM_CONTACTS] if sim_contacts else [])]
        self._inbox = Inbox(lcm, {c.channel: c for c in self._measured}, REPORT_CHANNEL)
        self._inputs = {p.name: p.declare_input(self) for c in COMMANDS for p in c.ports}
        for channel in self._measured:
            for index, port in enumerate(channel.ports):
                self._declare_output(channel, index, port)
        self._sent: dict[str, tuple[int, list[tuple[str, bytes]]]] = {}
        self._values: tuple[int, dict[str, tuple]] | None = None
        self._sending = False
        self.DeclarePeriodicPublishEvent(period, 0.0, self._exchange)
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._send_post)

    def _declare_output(self, channel: StationChannel, index: int, port: Port) -> None:
        # The measurements depend on the time only: the station's answer for that time.
        deps = {self.time_ticket()}
        port.declare_output(
            self, lambda context: self._measurement(context)[channel.channel][index], deps
        )

    def _send(self, context: Context, suffix: str, k: int) -> None:
        """Publish the commands as `context` has them, stamped with exchange `k`."""
        if self._sending:
            raise StationLinkError(
                "the controller's commands depend directly on the station's measurements "
                "(direct feedthrough): the lockstep needs commands that depend on the "
                "controller's state and the time only"
            )
        self._sending = True
        try:
            values = {name: port.Eval(context) for name, port in self._inputs.items()}
        finally:
            self._sending = False
        stamp = utime(k * self._period)
        sent = []
        for c in COMMANDS:
            message = c.encode(stamp, *(values[p.name] for p in c.ports))
            sent.append((c.channel + suffix, publish(self._lcm, c.channel + suffix, message)))
        self._sent[suffix] = (k, sent)

    def _send_pre(self, context: Context) -> None:
        k = _step_of(context.get_time(), self._period)
        if self._sent.get(PRE_SUFFIX, (None,))[0] != k:
            self._send(context, PRE_SUFFIX, k)

    def _exchange(self, context: Context) -> EventStatus:
        # Every exchange waits for the station's answer, read or not: DrakeLcm keeps only the
        # newest undelivered message of a channel, so no side may send a channel's next
        # message before the other has taken the last one.
        self._measurement(context)
        return EventStatus.Succeeded()

    def _send_post(self, context: Context, discrete_state) -> EventStatus:
        self._send(context, "", _step_of(context.get_time(), self._period))
        return EventStatus.Succeeded()

    def _measurement(self, context: Context) -> dict[str, tuple]:
        """The station's measurements at the exchange of `context`'s time (waiting for them)."""
        k = _step_of(context.get_time(), self._period)
        if self._values is not None and self._values[0] == k:
            return self._values[1]
        if not self._greeted:
            self._greet()
        # Whatever reads a measurement before this client's publish event at this time (another
        # system's publish event) reads it in the same state: send the commands from here.
        self._send_pre(context)
        self._wait([c.channel for c in self._measured], utime(k * self._period), first=k == 0)
        values = {c.channel: self._inbox.decoded(c.channel, c) for c in self._measured}
        self._values = (k, values)
        return values

    def _greet(self) -> None:
        """Step 0 of the protocol (`greet_station`)."""
        greet_station(self._lcm, self._inbox, self._identity, self._timeouts)
        self._greeted = True

    def _wait(self, names: list[str], stamp: int, first: bool) -> None:
        limit = self._timeouts.start if first else self._timeouts.step
        start = time.monotonic()
        resend_at = start + self._timeouts.resend
        while True:
            self._inbox.raise_errors()
            missing = self._inbox.missing(names, stamp)
            if not missing:
                return
            now = time.monotonic()
            if now - start > limit:
                raise StationLinkError(self._silence(missing, stamp, limit, first))
            if now >= resend_at:
                # A lost datagram: send the last commands again (the station answers a repeat).
                for suffix in ("", PRE_SUFFIX):
                    for channel, data in self._sent.get(suffix, (0, []))[1]:
                        self._lcm.Publish(channel, data)
                resend_at = now + self._timeouts.resend
            wait = min(limit - (now - start), resend_at - now)
            self._lcm.HandleSubscriptions(max(1, int(wait * 1000)))

    def _silence(self, missing: list[str], stamp: int, limit: float, first: bool) -> str:
        url = self._lcm.get_lcm_url()
        if first:
            return no_station(url, missing, limit)
        return (
            f"the cell station stopped answering on {url}: nothing on {', '.join(missing)} "
            f"for {limit:g} s at t = {stamp / 1e6:.3f} s (it died or was stopped)"
        )

    def end_session(self, timeout: float | None = None) -> dict:
        """Tell the station the run is over and return its report (a dict); StationLinkError
        if it does not answer within `timeout` (default: the step timeout)."""
        limit = self._timeouts.step if timeout is None else timeout
        k = self._values[0] if self._values is not None else 0
        return request_report(self._lcm, self._inbox, utime(k * self._period), limit)


def make_cell_station_interface(
    scenario: Scenario,
    lcm: DrakeLcm,
    *,
    timeouts: LockstepTimeouts | None = None,
    sim_contacts: bool = False,
    identity: ScenarioIdentity | None = None,
) -> Diagram:
    """The station of `scenario` as seen over `lcm` (see the module docstring): the
    controller-facing ports of `make_cell_station`, same names and types; with `sim_contacts`
    also `sim.contacts` (the touching pairs by owner, for a run's collision watch). Its
    client system is named "station_client" (`end_station_session` finds it). Before the
    first step it tells the station `identity` (default: `scenario`'s) and refuses a station
    that serves another scenario (`ScenarioMismatch`)."""
    if identity is None:
        identity = ScenarioIdentity.of(scenario)
    builder = DiagramBuilder()
    client = builder.AddNamedSystem(
        "station_client",
        StationClient(lcm, exchange_period(scenario), timeouts, sim_contacts, identity),
    )
    for index in range(client.num_input_ports()):
        port = client.get_input_port(index)
        builder.ExportInput(port, port.get_name())
    for index in range(client.num_output_ports()):
        port = client.get_output_port(index)
        builder.ExportOutput(port, port.get_name())
    diagram = builder.Build()
    diagram.set_name("cell_station_interface")
    return diagram


def end_station_session(interface: Diagram, timeout: float | None = None) -> dict:
    """End the session of a `make_cell_station_interface` diagram: the station stops serving
    and its report (simulated time, exchanges, and from a simulated station its fault record
    and safety function's log: `hrc_drake.cell.link.station_record`) is returned."""
    return interface.GetSubsystemByName("station_client").end_session(timeout)
