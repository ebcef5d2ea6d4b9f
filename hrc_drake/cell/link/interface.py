"""The cell station over LCM: the controller in one process, the station in another.

`make_cell_station_interface(scenario, lcm)` is, like Drake's `MakeHardwareStationInterface`, a
diagram with the station's controller-facing ports (`docs/station.md`): it publishes what the
controller commands and gives back what the station measured, over LCM (`lcm_messages`).
`serve_cell_station(station, lcm, period)` is the other side: it feeds the commands it receives
to the station's inputs, advances the station, and publishes its measured outputs.

Lockstep. Both sides are discrete systems whose events fall on multiples of the plant's time step
`h` (the exchange period), and in one process Drake handles the events at a time t in a fixed
order: publish events at the end of the step that reaches t, then every unrestricted update at t
(each computed from the same state), then every discrete update at t. The protocol keeps that
order across the two processes, so that each side reads at each t exactly what it would read in
one diagram; the two-process run then equals the in-process one:

0. Before the first step the controller says which scenario it runs (a "hello" session message
   with its `ScenarioIdentity`, `hrc_drake.cell.link.scenario_identity`), sent again until the
   station answers with its own; each side compares the two, and a pair that differs stops on
   both sides with `ScenarioMismatch`, one line naming what differs. A station that serves no
   scenario (identity None: a real cell's driver, a test's stand-in) answers `{}` and serves any
   controller.
1. At the end of the step reaching t (the interface's publish event) the controller sends its
   commands as they stand before its updates at t, on `<channel>_PRE`, stamped t, and waits for
   the answer (at every exchange, read or not: DrakeLcm keeps only the newest undelivered
   message of a channel, so neither side may send a channel's next message before the other
   has taken the last; for the same reason each direction has channels of its own).
2. The station sets its inputs to them (its outputs with direct feedthrough, e.g. grip detection
   from the commanded opening, and its own unrestricted updates at t read them, as in one
   diagram), and publishes its measurements at t, stamped t.
3. The controller's updates at t read those measurements: the interface's outputs wait for the
   measurements stamped with the context's time (a timeout ends in `StationLinkError`).
4. In the discrete updates at t the controller sends its commands as its unrestricted updates
   left them, on `<channel>`, stamped t: what the station's discrete update at t (the plant's
   step) reads. The station's command hold switches to them in an unrestricted update at t, so
   the station's other unrestricted updates at t still read the commands of step 1.
5. The station advances to t + h (applying its welds through its `Simulator` monitor) and
   waits for step 1 at t + h.

This reproduces the one-process run exactly when the controller's outputs depend on its state
and the time only (no direct feedthrough of the measurements: the Supervisor's do not) and change
only in unrestricted updates, and every update on either side falls on a multiple of h. Lost
datagrams are sent again after `LockstepTimeouts.resend`; a side that does not answer within
`LockstepTimeouts.start` (the first message) or `.step` (each later one) ends the run with a
one-line `StationLinkError`; the station's own errors are sent to the controller and end its
run with the station's message.
"""

from __future__ import annotations

import json
import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import (
    BasicVector,
    Context,
    Diagram,
    DiagramBuilder,
    EventStatus,
    LeafSystem,
)

from hrc_drake.cell.link.lcm_messages import (
    COMMANDS,
    END_CHANNEL,
    MEASUREMENTS,
    PRE_SUFFIX,
    REPORT_CHANNEL,
    SIM_CONTACTS,
    Contacts,
    LcmDecodeError,
    Port,
    StationChannel,
    lcmt_station_session,
    session_message,
    utime,
)
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity, mismatch
from hrc_drake.scenario.schema import Scenario, ScenarioError

# Host-local multicast (ttl=0: the datagrams never leave this machine), on a port of its own so
# that another LCM user's default group (239.255.76.67:7667) does not mix in.
DEFAULT_LCM_URL = "udpm://239.241.129.92:20185?ttl=0"


class StationLinkError(RuntimeError):
    """The other side of the station link is missing, died, or is out of step."""


class ScenarioMismatch(StationLinkError):
    """The station and the controller were started with different scenarios (or options):
    refused before the first step, on both sides."""


HELLO = "hello"
"""The session message that carries a side's `ScenarioIdentity` (JSON; `{}` for none)."""


def _identity_text(identity: ScenarioIdentity | None) -> str:
    return "{}" if identity is None else identity.to_json()


def _their_identity(message) -> ScenarioIdentity | None:
    """The identity in the other side's hello; StationLinkError if it is not one."""
    try:
        return ScenarioIdentity.from_json(message.text)
    except (ValueError, TypeError) as err:
        raise StationLinkError(
            f"the other side's hello is not a scenario identity ({err}); both sides must run "
            "the same hrc_drake version"
        ) from None


@dataclass(frozen=True)
class LockstepTimeouts:
    """Wall-clock limits of the lockstep [s]: `start` for the other side's first message,
    `step` for each later one, `resend` between resending the last messages while waiting."""

    start: float = 60.0
    step: float = 30.0
    resend: float = 0.5


def exchange_period(scenario: Scenario) -> float:
    """The lockstep's exchange period: the plant's time step. The controller's period must be
    a whole number of them, exactly in floating point, so that every update of either side
    falls on an exchange; ScenarioError naming the keys otherwise."""
    step, period = scenario.physics.time_step, scenario.run.period
    count = round(period / step)
    if count < 1 or count * step != period:
        raise ScenarioError(
            f"run.period {period} s is not a whole number of physics.time_step {step} s: the "
            "station over LCM exchanges at every plant step; choose run.period = n × time_step"
        )
    return step


class _Inbox:
    """The newest message of each channel with its stamp and how many came, kept by LCM
    handlers that never throw (a message that cannot be read is kept as the error it gives),
    and the session messages."""

    def __init__(self, lcm: DrakeLcm, channels: dict[str, StationChannel], session: str):
        self.lcm = lcm
        self.latest: dict[str, tuple[int, bytes]] = {}
        self.count: dict[str, int] = dict.fromkeys(channels, 0)
        self.session: list = []
        self.errors: list[str] = []
        self.on_message: Callable[[], None] | None = None
        for name, channel in channels.items():
            lcm.Subscribe(name, lambda data, c=channel, n=name: self._keep(c, n, data))
        self._session_channel = session
        lcm.Subscribe(session, self._keep_session)

    def _keep(self, channel: StationChannel, name: str, data: bytes) -> None:
        try:
            self.latest[name] = (channel.stamp_of(data), data)
            self.count[name] += 1
        except LcmDecodeError as err:
            self.errors.append(f"{name}: {err}")
        if self.on_message is not None:
            self.on_message()

    def _keep_session(self, data: bytes) -> None:
        try:
            self.session.append(lcmt_station_session.decode(data))
        except LcmDecodeError as err:
            self.errors.append(f"{self._session_channel}: {err}")
        if self.on_message is not None:
            self.on_message()

    def stamp(self, name: str) -> int | None:
        """The stamp of the newest message on `name` (None: none yet)."""
        entry = self.latest.get(name)
        return None if entry is None else entry[0]

    def missing(self, names: list[str], stamp: int) -> list[str]:
        """The channels of `names` whose newest message is not stamped `stamp`;
        StationLinkError if one is stamped later (the two sides are out of step)."""
        ahead = [n for n in names if n in self.latest and self.latest[n][0] > stamp]
        if ahead:
            raise StationLinkError(
                f"out of step: {', '.join(ahead)} stamped after {stamp} us; is a second "
                f"controller or station on {self.lcm.get_lcm_url()}? give each pair its own URL"
            )
        return [n for n in names if self.stamp(n) != stamp]

    def decoded(self, name: str, channel: StationChannel) -> tuple:
        """The port values of the newest message on `name`."""
        return channel.decode(channel.message.decode(self.latest[name][1]))

    def raise_errors(self, session_errors: bool = True) -> None:
        """StationLinkError for an unreadable message or (`session_errors`) an error the other
        side reported."""
        if self.errors:
            raise StationLinkError(self.errors[0])
        for message in self.session if session_errors else ():
            if message.kind == "error":
                raise StationLinkError(f"the cell station stopped: {message.text}")

    def has_session(self, kind: str) -> bool:
        """Whether a session message of `kind` came."""
        return any(m.kind == kind for m in self.session)


def _publish(lcm: DrakeLcm, channel: str, message) -> bytes:
    data = message.encode()
    lcm.Publish(channel, data)
    return data


def _declare_port_input(system: LeafSystem, port: Port):
    if port.size is not None:
        return system.DeclareVectorInputPort(port.name, BasicVector(port.size))
    return system.DeclareAbstractInputPort(port.name, AbstractValue.Make(port.model()))


def _step_of(t: float, period: float) -> int:
    """The exchange at or just before time `t` (events fall on multiples of `period`)."""
    return int(np.floor(t / period + 1e-6))


class StationClient(LeafSystem):
    """The controller's side of the lockstep (see the module docstring): input ports are the
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
        self._inbox = _Inbox(lcm, {c.channel: c for c in self._measured}, REPORT_CHANNEL)
        self._inputs = {p.name: _declare_port_input(self, p) for c in COMMANDS for p in c.ports}
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

        def calc(context, output):
            value = self._measurement(context)[channel.channel][index]
            if port.size is not None:
                output.SetFromVector(value)
            else:
                output.set_value(value)

        if port.size is not None:
            self.DeclareVectorOutputPort(
                port.name, BasicVector(port.size), calc, prerequisites_of_calc=deps
            )
        else:
            model = port.model
            self.DeclareAbstractOutputPort(
                port.name, lambda: AbstractValue.Make(model()), calc, prerequisites_of_calc=deps
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
            sent.append((c.channel + suffix, _publish(self._lcm, c.channel + suffix, message)))
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
        """Step 0 of the protocol: send this controller's identity until the station answers
        with its own (a station started later, or a lost datagram, needs it again);
        ScenarioMismatch, naming what differs, if the two run different scenarios."""
        hello = session_message(0, HELLO, _identity_text(self._identity))
        limit, start = self._timeouts.start, time.monotonic()
        resend_at = start
        while True:
            self._inbox.raise_errors()
            answers = [m for m in self._inbox.session if m.kind == HELLO]
            if answers:
                theirs = _their_identity(answers[-1])
                problem = (
                    None
                    if self._identity is None
                    else mismatch(self._identity, theirs, "controller")
                )
                if problem is not None:
                    raise ScenarioMismatch(problem)
                self._greeted = True
                return
            now = time.monotonic()
            if now - start > limit:
                raise StationLinkError(self._silence([REPORT_CHANNEL], 0, limit, first=True))
            if now >= resend_at:
                _publish(self._lcm, END_CHANNEL, hello)
                resend_at = now + self._timeouts.resend
            wait = min(limit - (now - start), resend_at - now)
            self._lcm.HandleSubscriptions(max(1, int(wait * 1000)))

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
            return (
                f"no cell station answered on {url} within {limit:g} s (nothing on "
                f"{', '.join(missing)}): start one with `hrc-drake station --scenario S "
                f"--lcm {shlex.quote(url)}`"
            )
        return (
            f"the cell station stopped answering on {url}: nothing on {', '.join(missing)} "
            f"for {limit:g} s at t = {stamp / 1e6:.3f} s (it died or was stopped)"
        )

    def end_session(self, timeout: float | None = None) -> dict:
        """Tell the station the run is over and return its report (a dict); StationLinkError
        if it does not answer within `timeout` (default: the step timeout)."""
        limit = self._timeouts.step if timeout is None else timeout
        k = self._values[0] if self._values is not None else 0
        _publish(self._lcm, END_CHANNEL, session_message(utime(k * self._period), "end"))
        start = time.monotonic()
        while time.monotonic() - start < limit:
            self._inbox.raise_errors()
            reports = [m for m in self._inbox.session if m.kind == "report"]
            if reports:
                return json.loads(reports[-1].text)
            self._lcm.HandleSubscriptions(50)
        raise StationLinkError(
            f"the cell station did not confirm the end of the run on "
            f"{self._lcm.get_lcm_url()} within {limit:g} s"
        )


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
    and its report (simulated time, exchanges) is returned."""
    return interface.GetSubsystemByName("station_client").end_session(timeout)


def _default_commands() -> dict[str, object]:
    return {
        p.name: np.zeros(p.size) if p.size is not None else p.model()
        for c in COMMANDS
        for p in c.ports
    }


class CommandHold(LeafSystem):
    """The station side's command inputs: output ports named like the station's command
    inputs, from the held commands. The server sets the held commands (`hold`) and the
    commands to switch to (`pending`); an unrestricted update every `period` switches, so that
    the station's other unrestricted updates at that time still read the held ones."""

    def __init__(self, period: float):
        super().__init__()
        empty = AbstractValue.Make(_default_commands())
        self._held = self.DeclareAbstractState(empty)
        self._pending = self.DeclareAbstractState(empty)
        deps = {self.abstract_state_ticket(self._held)}
        for port in (p for c in COMMANDS for p in c.ports):

            def calc(context, output, name=port.name, vector=port.size is not None):
                value = context.get_abstract_state(self._held).get_value()[name]
                output.SetFromVector(value) if vector else output.set_value(value)

            if port.size is not None:
                self.DeclareVectorOutputPort(
                    port.name, BasicVector(port.size), calc, prerequisites_of_calc=deps
                )
            else:
                self.DeclareAbstractOutputPort(
                    port.name,
                    lambda model=port.model: AbstractValue.Make(model()),
                    calc,
                    prerequisites_of_calc=deps,
                )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._switch)

    def _switch(self, context, state) -> None:
        pending = context.get_abstract_state(self._pending).get_value()
        state.get_mutable_abstract_state(self._held).set_value(pending)

    def hold(self, context: Context, commands: dict[str, object]) -> None:
        """Hold `commands` now (in this system's `context`)."""
        context.SetAbstractState(self._held, commands)

    def switch_to(self, context: Context, commands: dict[str, object]) -> None:
        """Switch to `commands` at the next update."""
        context.SetAbstractState(self._pending, commands)


@dataclass(frozen=True)
class StationHooks:
    """What a simulated station needs besides its ports: weld switching through the
    `Simulator` monitor (`welds_changed(root)`, then `apply_welds(root)`), and the touching
    pairs for a run's collision watch (`contacts(root)`)."""

    welds_changed: Callable[[Context], bool] | None = None
    apply_welds: Callable[[Context], None] | None = None
    contacts: Callable[[Context], Contacts] | None = None


def _check_station_ports(diagram: Diagram) -> None:
    missing = [
        p.name
        for c in (*COMMANDS, *MEASUREMENTS)
        for p in c.ports
        if not (diagram.HasInputPort(p.name) or diagram.HasOutputPort(p.name))
    ]
    if missing:
        raise ValueError(
            f"the station diagram {diagram.get_name()!r} lacks the ports {', '.join(missing)} "
            "(docs/station.md lists what a station serves)"
        )


class CellStationServer:
    """The station's side of the lockstep (see the module docstring). It works from the LCM
    handlers: `serve()` pumps `lcm` until the controller ends the session; over `memq://` the
    controller's client pumps the same `lcm` and so drives it (a one-process test). `identity`
    is the scenario it serves: a controller of another is refused (`ScenarioMismatch`); None
    (a stand-in, a real cell) serves any controller."""

    def __init__(
        self,
        station: Diagram,
        lcm: DrakeLcm,
        period: float,
        hooks: StationHooks | None = None,
        timeouts: LockstepTimeouts | None = None,
        identity: ScenarioIdentity | None = None,
    ):
        _check_station_ports(station)
        self._identity, self._greeted, self._hellos = identity, False, 0
        self._lcm, self._period, self._station = lcm, period, station
        self._hooks = hooks if hooks is not None else StationHooks()
        self._timeouts = timeouts if timeouts is not None else LockstepTimeouts()
        builder = DiagramBuilder()
        builder.AddSystem(station)
        self._hold = builder.AddNamedSystem("command_hold", CommandHold(period))
        for name in _default_commands():
            builder.Connect(self._hold.GetOutputPort(name), station.GetInputPort(name))
        self._simulator = Simulator(builder.Build())
        self._root = self._simulator.get_mutable_context()
        self._station_context = station.GetMyContextFromRoot(self._root)
        self._hold_context = self._hold.GetMyMutableContextFromRoot(self._root)
        if self._hooks.welds_changed is not None:
            self._simulator.set_monitor(self._watch_welds)
        self._pre = [c.channel + PRE_SUFFIX for c in COMMANDS]
        self._post = [c.channel for c in COMMANDS]
        commands = {c.channel + s: c for c in COMMANDS for s in (PRE_SUFFIX, "")}
        self._inbox = _Inbox(lcm, commands, END_CHANNEL)
        self._inbox.on_message = self._on_message
        self._k, self._awaiting, self._started = 0, "pre", False
        self._sent: list[tuple[str, bytes]] = []
        self._pre_counts: list[int] = []
        self._last_progress = time.monotonic()
        self.error: Exception | None = None
        self.report: dict | None = None

    @property
    def finished(self) -> bool:
        """The session ended (by the controller, or by an error)."""
        return self.report is not None or self.error is not None

    @property
    def root_context(self) -> Context:
        """The server diagram's root context (the station's is inside it)."""
        return self._root

    def _watch_welds(self, root: Context) -> EventStatus:
        if self._hooks.welds_changed(root):
            return EventStatus.ReachedTermination(self._hold, "welds")
        return EventStatus.DidNothing()

    def _on_message(self) -> None:
        if self.finished:
            return
        try:
            self._progress()
        except Exception as err:  # an LCM handler must not throw: report it and stop
            self._fail(err)

    def _fail(self, err: Exception) -> None:
        self.error = err
        if isinstance(err, ScenarioMismatch):
            # The controller finds the mismatch in the hello just sent, and says it its own
            # way; an error sent now could replace that hello before it is read (DrakeLcm keeps
            # only a channel's newest undelivered message).
            return
        lines = str(err).strip().splitlines() or [type(err).__name__]
        text = f"{type(err).__name__}: {lines[-1]}" if len(lines) > 1 else lines[0]
        stamp = utime(self._root.get_time())
        _publish(self._lcm, REPORT_CHANNEL, session_message(stamp, "error", text))

    def _progress(self) -> None:
        """Take every step of the protocol whose messages are in."""
        while not self.finished:
            self._inbox.raise_errors(session_errors=False)
            if self._inbox.has_session("end"):
                self._end()
                return
            if not self._started:
                self._answer_hellos()
            if not self._greeted:
                return
            stamp = utime(self._k * self._period)
            if self._awaiting == "pre":
                if self._inbox.missing(self._pre, stamp):
                    return
                self._take_pre()
            else:
                if self._inbox.missing(self._post, stamp):
                    self._answer_repeat()
                    return
                self._hold.switch_to(self._hold_context, self._commands(""))
                self._advance()
                self._k, self._awaiting = self._k + 1, "pre"
            self._last_progress = time.monotonic()

    def _answer_hellos(self) -> None:
        """Step 0 of the protocol: answer each hello that came with this station's identity
        (a repeated hello means the answer was lost); ScenarioMismatch, naming what differs,
        if the controller runs another scenario."""
        hellos = [m for m in self._inbox.session if m.kind == HELLO]
        for message in hellos[self._hellos :]:
            stamp = utime(self._root.get_time())
            reply = session_message(stamp, HELLO, _identity_text(self._identity))
            _publish(self._lcm, REPORT_CHANNEL, reply)
            theirs = _their_identity(message)
            if self._identity is not None and theirs is not None:
                problem = mismatch(self._identity, theirs, "station")
                if problem is not None:
                    raise ScenarioMismatch(problem)
            self._greeted = True
        self._hellos = len(hellos)

    def _commands(self, suffix: str) -> dict[str, object]:
        values = {}
        for c in COMMANDS:
            values.update(
                zip(
                    (p.name for p in c.ports),
                    self._inbox.decoded(c.channel + suffix, c),
                    strict=True,
                )
            )
        return values

    def _take_pre(self) -> None:
        self._hold.hold(self._hold_context, self._commands(PRE_SUFFIX))
        if not self._started:
            self._simulator.Initialize()
            if self._hooks.apply_welds is not None:
                # A new context has every constraint on: start from the welds wanted.
                self._hooks.apply_welds(self._root)
            self._started = True
        self._publish_measurements()
        self._pre_counts = [self._inbox.count[n] for n in self._pre]
        self._awaiting = "post"

    def _answer_repeat(self) -> None:
        """The controller sent all its commands before its update again (a datagram was
        lost): send the measurements again."""
        counts = [self._inbox.count[n] for n in self._pre]
        if all(now > before for now, before in zip(counts, self._pre_counts, strict=True)):
            self._pre_counts = counts
            for channel, data in self._sent:
                self._lcm.Publish(channel, data)

    def _advance(self) -> None:
        target = (self._k + 1) * self._period
        while self._root.get_time() < target:
            self._simulator.AdvanceTo(target)
            self._apply_welds()

    def _apply_welds(self) -> None:
        hooks = self._hooks
        if hooks.welds_changed is not None and hooks.welds_changed(self._root):
            hooks.apply_welds(self._root)

    def _publish_measurements(self) -> None:
        stamp = utime(self._k * self._period)
        sent = []
        for c in MEASUREMENTS:
            values = [
                self._station.GetOutputPort(p.name).Eval(self._station_context) for p in c.ports
            ]
            sent.append((c.channel, _publish(self._lcm, c.channel, c.encode(stamp, *values))))
        if self._hooks.contacts is not None:
            contacts = SIM_CONTACTS.encode(stamp, self._hooks.contacts(self._root))
            sent.append((SIM_CONTACTS.channel, _publish(self._lcm, SIM_CONTACTS.channel, contacts)))
        self._sent = sent

    def _end(self) -> None:
        self.report = {"sim_time": self._root.get_time(), "exchanges": self._k}
        stamp = utime(self._root.get_time())
        _publish(self._lcm, REPORT_CHANNEL, session_message(stamp, "report", self.report))

    def serve(self) -> dict:
        """Serve until the controller ends the session; its report. StationLinkError if no
        controller comes or it stops answering; the station's own errors are raised (after
        being sent to the controller)."""
        while not self.finished:
            first = self._k == 0 and self._awaiting == "pre"
            limit = self._timeouts.start if first else self._timeouts.step
            if time.monotonic() - self._last_progress > limit:
                self._fail(StationLinkError(self._silence(limit, first)))
                break
            self._lcm.HandleSubscriptions(100)
        if self.error is not None:
            raise self.error
        return self.report

    def _silence(self, limit: float, first: bool) -> str:
        url = self._lcm.get_lcm_url()
        if first:
            return (
                f"no controller came on {url} within {limit:g} s: run `hrc-drake simulate "
                f"--scenario S --station-lcm {shlex.quote(url)}`"
            )
        return (
            f"the controller stopped answering on {url} at t = {self._root.get_time():.3f} s "
            f"(nothing for {limit:g} s; it died or was stopped)"
        )


def cell_station_hooks(station) -> StationHooks:
    """The hooks of a `CellStation` (`hrc_drake.cell.station.build`): its welds, and the touching
    pairs of `sim.contact_results` by owner."""
    from hrc_drake.cell.station.contacts import geometry_owners, owner_pairs

    owners = geometry_owners(station.plant)
    results_port = station.diagram.GetOutputPort("sim.contact_results")

    def contacts(root: Context) -> Contacts:
        results = results_port.Eval(station.diagram.GetMyContextFromRoot(root))
        return tuple(owner_pairs(results, owners))

    applied = [frozenset()]  # the welds applied last

    def welds_changed(root: Context) -> bool:
        return station.welds_changed(root, applied[0])

    def apply_welds(root: Context) -> None:
        applied[0] = station.apply_welds(root)

    return StationHooks(welds_changed, apply_welds, contacts)


def serve_cell_station(
    station,
    lcm: DrakeLcm,
    period: float,
    timeouts: LockstepTimeouts | None = None,
    identity: ScenarioIdentity | None = None,
) -> dict:
    """Serve `station` (a `CellStation`, or a bare station diagram with the same ports) over
    `lcm` until the controller ends the session, exchanging every `period` (the plant's time
    step: `exchange_period(scenario)`); the session's report. `identity`: the scenario it
    serves, which the controller must run (`ScenarioMismatch` otherwise)."""
    if isinstance(station, Diagram):
        server = CellStationServer(station, lcm, period, timeouts=timeouts, identity=identity)
        return server.serve()
    hooks = cell_station_hooks(station)
    return CellStationServer(station.diagram, lcm, period, hooks, timeouts, identity).serve()
