"""The cell station over LCM, the station's side: `serve_cell_station(station, lcm, period)` feeds
the commands it receives from the controller's process (`hrc_drake.cell.link.interface`) to the
station's inputs, advances the station, and publishes its measured outputs, in the lockstep of
`hrc_drake.cell.link.lockstep`.

`CellStationServer` does it for any diagram with the station's ports (a real cell's stand-in, a
test's fake); `cell_station_hooks` adds what a simulated `CellStation` needs besides its ports
(weld switching, the touching pairs) and what it tells besides them (its fault record and safety
function's log, in the session's report: `hrc_drake.cell.link.station_record`). Apart from
the controller's side because the two run in different processes and share only the protocol
and the messages.
"""

from __future__ import annotations

import enum
import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator, SimulatorConfig
from pydrake.systems.framework import (
    Context,
    Diagram,
    DiagramBuilder,
    EventStatus,
    LeafSystem,
)

from hrc_drake.cell.link.channels import (
    COMMANDS,
    END_CHANNEL,
    MEASUREMENTS,
    PRE_SUFFIX,
    REPORT_CHANNEL,
    SIM_CONTACTS,
)
from hrc_drake.cell.link.lcm_messages import Contacts, session_message, utime
from hrc_drake.cell.link.lockstep import (
    HELLO,
    Inbox,
    LockstepTimeouts,
    ScenarioMismatch,
    StationLinkError,
    check_hello,
    identity_text,
    publish,
)
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.scenario import cell_configs, configured_simulator

if TYPE_CHECKING:
    from hrc_drake.cell.link.station_record import StationRecord


def _default_commands() -> dict[str, object]:
    return {
        p.name: np.zeros(p.size) if p.size is not None else p.model()
        for c in COMMANDS
        for p in c.ports
    }


class _Awaiting(enum.Enum):
    """Which of a lockstep step's two command sets the station waits for."""

    PRE = "pre"  # the commands as they stood before the controller's updates at t (`_PRE`)
    POST = "post"  # the commands as the controller's updates at t left them


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
            port.declare_output(self, lambda c, name=port.name: self._held_of(c)[name], deps)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._switch)

    def _held_of(self, context) -> dict[str, object]:
        return context.get_abstract_state(self._held).get_value()

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
    `Simulator` monitor (`welds_changed(root)`, then `apply_welds(root)`), the touching
    pairs for a run's collision watch (`contacts(root)`), and its fault record and safety
    function's log for the session's report (`record(root)`), and the scenario's
    `simulator_config` for the server's simulator."""

    welds_changed: Callable[[Context], bool] | None = None
    apply_welds: Callable[[Context], None] | None = None
    contacts: Callable[[Context], Contacts] | None = None
    record: Callable[[Context], StationRecord] | None = None
    simulator_config: SimulatorConfig | None = None

    def simulator(self, diagram: Diagram) -> Simulator:
        """A Simulator of `diagram`, with `simulator_config` applied when there is one."""
        return configured_simulator(self.simulator_config, diagram)


def check_station_ports(diagram: Diagram) -> None:
    """ValueError naming the station ports `diagram` lacks (of the commands and measurements
    the link carries)."""
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
    """The station's side of the lockstep (`hrc_drake.cell.link.lockstep`). It works from the LCM
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
        check_station_ports(station)
        self._identity, self._greeted, self._hellos = identity, False, 0
        self._lcm, self._period, self._station = lcm, period, station
        self._hooks = hooks if hooks is not None else StationHooks()
        self._timeouts = timeouts if timeouts is not None else LockstepTimeouts()
        builder = DiagramBuilder()
        builder.AddSystem(station)
        self._hold = builder.AddNamedSystem("command_hold", CommandHold(period))
        for name in _default_commands():
            builder.Connect(self._hold.GetOutputPort(name), station.GetInputPort(name))
        self._simulator = self._hooks.simulator(builder.Build())
        self._root = self._simulator.get_mutable_context()
        self._station_context = station.GetMyContextFromRoot(self._root)
        self._hold_context = self._hold.GetMyMutableContextFromRoot(self._root)
        if self._hooks.welds_changed is not None:
            self._simulator.set_monitor(self._watch_welds)
        self._pre = [c.channel + PRE_SUFFIX for c in COMMANDS]
        self._post = [c.channel for c in COMMANDS]
        commands = {c.channel + s: c for c in COMMANDS for s in (PRE_SUFFIX, "")}
        self._inbox = Inbox(lcm, commands, END_CHANNEL)
        self._inbox.on_message = self._on_message
        self._k, self._awaiting, self._started = 0, _Awaiting.PRE, False
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
        publish(self._lcm, REPORT_CHANNEL, session_message(stamp, "error", text))

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
            if self._awaiting == _Awaiting.PRE:
                if self._inbox.missing(self._pre, stamp):
                    return
                self._take_pre()
            else:
                if self._inbox.missing(self._post, stamp):
                    self._answer_repeat()
                    return
                self._hold.switch_to(self._hold_context, self._commands(""))
                self._advance()
                self._k, self._awaiting = self._k + 1, _Awaiting.PRE
            self._last_progress = time.monotonic()

    def _answer_hellos(self) -> None:
        """Step 0 of the protocol: answer each hello that came with this station's identity
        (a repeated hello means the answer was lost); ScenarioMismatch, naming what differs,
        if the controller runs another scenario."""
        hellos = [m for m in self._inbox.session if m.kind == HELLO]
        for message in hellos[self._hellos :]:
            stamp = utime(self._root.get_time())
            reply = session_message(stamp, HELLO, identity_text(self._identity))
            publish(self._lcm, REPORT_CHANNEL, reply)
            check_hello(self._identity, None, message)
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
        self._awaiting = _Awaiting.POST

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
            sent.append((c.channel, publish(self._lcm, c.channel, c.encode(stamp, *values))))
        if self._hooks.contacts is not None:
            contacts = SIM_CONTACTS.encode(stamp, self._hooks.contacts(self._root))
            sent.append((SIM_CONTACTS.channel, publish(self._lcm, SIM_CONTACTS.channel, contacts)))
        self._sent = sent

    def _end(self) -> None:
        # The station stands where the controller's run ended (it waits for the commands of
        # that time's updates): its record is the one a one-process run reads at its end.
        report = {"sim_time": self._root.get_time(), "exchanges": self._k}
        if self._hooks.record is not None:
            report.update(self._hooks.record(self._root).to_json())
        self.report = report
        stamp = utime(self._root.get_time())
        publish(self._lcm, REPORT_CHANNEL, session_message(stamp, "report", self.report))

    def serve(self) -> dict:
        """Serve until the controller ends the session; its report. StationLinkError if no
        controller comes or it stops answering; the station's own errors are raised (after
        being sent to the controller)."""
        while not self.finished:
            first = self._k == 0 and self._awaiting == _Awaiting.PRE
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
    """The hooks of a `CellStation` (`hrc_drake.cell.station.build`): its welds, the touching
    pairs of `sim.contact_results` by owner, and its `StationRecord`."""
    from hrc_drake.cell.link.station_record import StationRecord
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

    def record(root: Context) -> StationRecord:
        return StationRecord.of(station, root)

    config = cell_configs(station.scenario).simulator_config
    return StationHooks(welds_changed, apply_welds, contacts, record, config)


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
        return CellStationServer(station, lcm, period, None, timeouts, identity).serve()
    hooks = cell_station_hooks(station)
    return CellStationServer(station.diagram, lcm, period, hooks, timeouts, identity).serve()
