"""The cell station over LCM in real time, the station's side (the rules:
`hrc_drake.cell.link.realtime`; the controller's side: `hrc_drake.cell.link.realtime_client`).

`RealtimeStationServer` serves any diagram with the station's ports, paced to the wall clock,
through Drake's LCM systems: an `LcmSubscriberSystem` per command channel feeding
`RealtimeCommands` (the newest command of each channel, latched at every plant step, and the
arm's watchdog `ur3.command_stale`), and a `MessageEncoder` and an `LcmPublisherSystem` per
measured channel at its device's rate (`channel_rates`). `UR3_STATUS` carries beside the
measurement what the arm's servo followed when measured (`joint_position_desired` and
`joint_velocity_desired`, as RTDE's `target_q` and `target_qd`: the station's `sim.ur3.target`,
the command or its safety function's brake), which the controller's tracking check compares
with.

The session: the station answers the controller's hello (refusing another scenario, or a
controller in lockstep or at another pace); it then publishes its measurements at time 0 until
the controller's first commands come, holding the arm where it stands, and only then starts its
clock, so that both simulators start within a message's trip of each other. It serves until
the controller's `end` (its report, as the lockstep's, with its fault record and safety
function's log: `hrc_drake.cell.link.station_record`) or until no command has come for
`SILENCE` (one line naming the channel and the URL).
"""

from __future__ import annotations

import shlex
import time
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import (
    BasicVector,
    Context,
    Diagram,
    DiagramBuilder,
    EventStatus,
    LeafSystem,
)
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Multiplexer

from hrc_drake.cell.link.channels import (
    COMMANDS,
    END_CHANNEL,
    MEASUREMENTS,
    REPORT_CHANNEL,
    SIM_CONTACTS,
    Port,
    StationChannel,
)
from hrc_drake.cell.link.lcm_messages import N_JOINTS, session_message
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
from hrc_drake.cell.link.realtime import (
    ARM_COMMAND,
    SILENCE,
    STAMPED_CHANNELS,
    LinkClock,
    MessageEncoder,
    silent,
    stale_after,
    wall_utime,
)
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.link.station_server import (
    StationHooks,
    cell_station_hooks,
    check_station_ports,
)
from hrc_drake.cell.station.contacts import geometry_owners, owner_pairs
from hrc_drake.hri.messages import Prompt

# While waiting for the controller's first commands the station publishes its measurements
# at time 0 this often [s, wall clock].
WAITING_PUBLISH = 0.05


@dataclass(frozen=True)
class ArmSegment:
    """The arm's command as the station walks to the newest: from `q_from`, `v_from` held at
    `w_from` to `q_to`, `v_to` stamped `u_to` (wall-clock times [us])."""

    q_from: np.ndarray
    v_from: np.ndarray
    w_from: int
    q_to: np.ndarray
    v_to: np.ndarray
    u_to: int

    def at(self, w: int, early: int) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) at wall-clock time `w`: the newest once `w` is within `early` of its stamp
        (a command applies from its instant on, as in one process up to a step early)."""
        if w + early >= self.u_to or self.u_to <= self.w_from:
            return self.q_to, self.v_to
        f = max(0.0, (w - self.w_from) / (self.u_to - self.w_from))
        return self.q_from + f * (self.q_to - self.q_from), self.v_from + f * (
            self.v_to - self.v_from
        )

    def __deepcopy__(self, memo) -> ArmSegment:
        return self  # immutable once made


@dataclass(frozen=True)
class Latched:
    """What `RealtimeCommands` holds: the commands applied, whether the arm's is stale, the
    newest stamp of each channel, and the arm's segment (None before its first command)."""

    applied: dict
    stale: bool = False
    stamps: tuple[tuple[str, int], ...] = ()
    arm: ArmSegment | None = None

    def __deepcopy__(self, memo) -> Latched:
        return self  # replaced, never changed


class RealtimeCommands(LeafSystem):
    """The station's command inputs over the real-time link.

    Input ports: one per command channel, named after it (the message its LcmSubscriberSystem
    keeps). Output ports: the station's command ports (`ur3.position`, ...) and
    `ur3.command_stale` (1). Every plant `step` it latches the commands for that step (the
    plant's step then reads commands that stay put through it; before a channel's first
    message, `hold`): the gripper's and the prompt as the newest message has them, the arm's
    on the station's own time (`ArmSegment`, `clock`: the wall-clock time the step stands
    for). The arm's command is stale when the newest is older than `stale_after(rate, pace)`
    at that time (`rate`: the controller's)."""

    def __init__(self, hold: dict[str, object], step: float, rate: float, clock: LinkClock):
        super().__init__()
        self._clock, self._bound = clock, round(stale_after(rate, clock.pace) * 1e6)
        self._early = round(step / clock.pace * 1e6)
        self._messages = {
            c.channel: self.DeclareAbstractInputPort(c.channel, AbstractValue.Make(c.message()))
            for c in COMMANDS
        }
        self._latched = self.DeclareAbstractState(AbstractValue.Make(Latched(dict(hold))))
        deps = {self.abstract_state_ticket(self._latched)}
        for port in (p for c in COMMANDS for p in c.ports):
            port.declare_output(self, lambda c, name=port.name: self._state(c).applied[name], deps)
        self.DeclareVectorOutputPort(
            "ur3.command_stale",
            BasicVector(1),
            lambda context, output: output.SetFromVector([float(self._state(context).stale)]),
            prerequisites_of_calc=deps,
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(step, 0.0, self._latch)

    def _state(self, context) -> Latched:
        return context.get_abstract_state(self._latched).get_value()

    def _latch(self, context, state) -> None:
        latched = self._state(context)
        applied, stamps, arm = dict(latched.applied), dict(latched.stamps), latched.arm
        w = self._clock.stamp(context.get_time())
        for c in COMMANDS:
            message = self._messages[c.channel].Eval(context)
            if message.utime == 0 or message.utime == stamps.get(c.channel):
                continue  # none yet, or no newer one
            stamps[c.channel] = message.utime
            values = dict(zip((p.name for p in c.ports), c.decode(message), strict=True))
            if c.channel != ARM_COMMAND:
                applied.update(values)
                continue
            q, v = np.asarray(applied["ur3.position"]), np.asarray(applied["ur3.velocity"])
            q_to, v_to = values["ur3.position"], values["ur3.velocity"]
            arm = ArmSegment(q, v, w, q_to, v_to, message.utime)
        stale = False
        if arm is not None:
            applied["ur3.position"], applied["ur3.velocity"] = arm.at(w, self._early)
            stale = w - arm.u_to > self._bound
        new = Latched(applied, stale, tuple(stamps.items()), arm)
        state.get_mutable_abstract_state(self._latched).set_value(new)


def initial_hold(station: Diagram) -> dict[str, object]:
    """The commands that hold `station` as it starts: the arm where it stands, still, the
    fingers at their opening (at the RG2's least force: 0 is clipped to it), no prompt. Read
    from the exact ports where a sensor model (`sensors:`) sits on the measured ones."""
    context = station.CreateDefaultContext()

    def exact(name: str) -> np.ndarray:
        port = f"sim.{name}" if station.HasOutputPort(f"sim.{name}") else name
        return np.array(station.GetOutputPort(port).Eval(context), dtype=float)

    return {
        "ur3.position": exact("ur3.state_estimated")[:N_JOINTS],
        "ur3.velocity": np.zeros(N_JOINTS),
        "rg2.opening": exact("rg2.state_measured")[:1],
        "rg2.force": np.zeros(1),
        "hri.prompt": Prompt(),
    }


def measured_at(t: float, reading) -> float:
    """The simulated instant a reading published at `t` stands for: its own `stamp` where it
    carries one (a tracked body: when the tracker took it; a camera's configuration: its newest
    frame whose verdicts it reports), else `t`."""
    taken = getattr(reading, "stamp", None)
    return t if taken is None else taken


def _encoder(channel: StationChannel, clock: LinkClock) -> MessageEncoder:
    """The encoder of a measured channel, stamped with the wall-clock time its simulated
    instant stands for: the arm's status with the command it followed, the body and the
    configuration when they were measured (`measured_at`)."""
    if channel.channel == "UR3_STATUS":

        def status(clock, t, values):
            message = channel.encode(clock.stamp(t), *values[:3])
            message.joint_position_desired = [float(x) for x in values[3][:N_JOINTS]]
            message.joint_velocity_desired = [float(x) for x in values[3][N_JOINTS:]]
            return message

        target = Port("target", 2 * N_JOINTS)
        return MessageEncoder((*channel.ports, target), channel.message, status, clock)
    if channel.channel in STAMPED_CHANNELS:

        def stamped(clock, t, values):
            return channel.encode(clock.stamp(measured_at(t, values[0])), *values)

        return MessageEncoder(channel.ports, channel.message, stamped, clock)
    return MessageEncoder(
        channel.ports,
        channel.message,
        lambda clock, t, values: channel.encode(clock.stamp(t), *values),
        clock,
    )


def _contacts_encoder(owners: dict, clock: LinkClock) -> MessageEncoder:
    """The touching pairs by owner, from the station's `sim.contact_results`."""
    results = Port("sim.contact_results", model=ContactResults)
    return MessageEncoder(
        (results,),
        SIM_CONTACTS.message,
        lambda clock, t, values: SIM_CONTACTS.encode(
            clock.stamp(t), tuple(owner_pairs(values[0], owners))
        ),
        clock,
    )


class RealtimeStationServer:
    """Serves a station diagram over the real-time link (see the module docstring): `rates`
    are the channels' (`channel_rates`), `step` the plant's time step, `pace` the real-time
    rate; `hooks` those of a simulated station (`cell_station_hooks`: its welds and its
    record), `owners` its geometries' owners (to publish the touching pairs); `identity` the
    scenario it serves (None: any)."""

    def __init__(
        self,
        station: Diagram,
        lcm: DrakeLcm,
        rates: dict[str, float],
        step: float,
        pace: float,
        *,
        hooks: StationHooks | None = None,
        owners: dict | None = None,
        timeouts: LockstepTimeouts | None = None,
        identity: ScenarioIdentity | None = None,
    ):
        self._lcm, self._pace, self._identity = lcm, pace, identity
        self._hooks = hooks if hooks is not None else StationHooks()
        self._timeouts = timeouts if timeouts is not None else LockstepTimeouts()
        self._inbox = Inbox(lcm, {c.channel: c for c in COMMANDS}, END_CHANNEL)
        self._hellos = 0
        self._clock = LinkClock(pace)  # started as the station starts stepping
        check_station_ports(station)
        builder = DiagramBuilder()
        builder.AddSystem(station)
        bus = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
        self._commands = self._add_commands(builder, bus, station, step, rates[ARM_COMMAND])
        self._publishers = []
        self._add_measurements(builder, bus, station, rates, owners)
        self._simulator = self._hooks.simulator(builder.Build())
        self._root = self._simulator.get_mutable_context()
        self._simulator.set_monitor(self._watch)
        self._stop: str | None = None  # why the monitor stopped the simulation
        self._silent: tuple[str, float] = ("", 0.0)  # the channel that fell silent, its age
        self._lateness: list[int] = []  # [us] behind the wall clock, at each step
        self._started_wall = 0.0
        self.report: dict | None = None

    def _add_commands(self, builder, bus, station: Diagram, step: float, rate: float):
        """The command channels' subscribers into `RealtimeCommands`, into the station."""
        commands = RealtimeCommands(initial_hold(station), step, rate, self._clock)
        commands = builder.AddNamedSystem("realtime_commands", commands)
        for c in COMMANDS:
            subscriber = LcmSubscriberSystem.Make(c.channel, c.message, bus)
            subscriber = builder.AddNamedSystem(f"subscribe {c.channel}", subscriber)
            builder.Connect(subscriber.get_output_port(), commands.GetInputPort(c.channel))
            for p in c.ports:
                builder.Connect(commands.GetOutputPort(p.name), station.GetInputPort(p.name))
        if station.HasInputPort("ur3.command_stale"):
            builder.Connect(
                commands.GetOutputPort("ur3.command_stale"),
                station.GetInputPort("ur3.command_stale"),
            )
        return commands

    def _add_measurements(self, builder, bus, station: Diagram, rates, owners) -> None:
        """An encoder and a publisher per measured channel (and, with `owners`, the touching
        pairs), each at its rate."""
        for c in MEASUREMENTS:
            encoder = builder.AddNamedSystem(f"encode {c.channel}", _encoder(c, self._clock))
            for p in c.ports:
                builder.Connect(station.GetOutputPort(p.name), encoder.GetInputPort(p.name))
            if c.channel == "UR3_STATUS":
                self._connect_target(builder, station, self._commands, encoder)
            self._publish(builder, bus, c, encoder, rates[c.channel])
        if owners is not None:
            encoder = _contacts_encoder(owners, self._clock)
            encoder = builder.AddNamedSystem("encode SIM_CONTACTS", encoder)
            builder.Connect(
                station.GetOutputPort("sim.contact_results"),
                encoder.GetInputPort("sim.contact_results"),
            )
            self._publish(builder, bus, SIM_CONTACTS, encoder, rates[SIM_CONTACTS.channel])

    @staticmethod
    def _connect_target(builder, station: Diagram, commands, encoder) -> None:
        """What the arm's servo follows, for `UR3_STATUS`: the station's `sim.ur3.target` (the
        command, or its safety function's brake or blend), else the command it holds."""
        if station.HasOutputPort("sim.ur3.target"):
            builder.Connect(station.GetOutputPort("sim.ur3.target"), encoder.GetInputPort("target"))
            return
        mux = builder.AddNamedSystem("held target", Multiplexer([N_JOINTS, N_JOINTS]))
        builder.Connect(commands.GetOutputPort("ur3.position"), mux.get_input_port(0))
        builder.Connect(commands.GetOutputPort("ur3.velocity"), mux.get_input_port(1))
        builder.Connect(mux.get_output_port(), encoder.GetInputPort("target"))

    def _publish(self, builder, bus, channel: StationChannel, encoder, rate: float) -> None:
        publisher = LcmPublisherSystem.Make(
            channel.channel, channel.message, bus, publish_period=1.0 / rate
        )
        publisher = builder.AddNamedSystem(f"publish {channel.channel}", publisher)
        builder.Connect(encoder.get_output_port(), publisher.get_input_port())
        self._publishers.append(publisher)

    @property
    def root_context(self) -> Context:
        """The server diagram's root context (the station's is inside it)."""
        return self._root

    def _watch(self, root: Context) -> EventStatus:
        """The simulator's monitor: stop for the controller's end, its silence, or welds."""
        gone = None
        if self._started_wall:
            gone = silent(self._inbox.arrived, time.monotonic())
            self._lateness.append(self._clock.now() - self._clock.stamp(root.get_time()))
        if self._inbox.has_session("end"):
            self._stop = "end"
        elif gone is not None:
            self._stop, self._silent = "silent", gone
        elif self._hooks.welds_changed is not None and self._hooks.welds_changed(root):
            return EventStatus.ReachedTermination(self._commands, "welds")
        else:
            return EventStatus.DidNothing()
        return EventStatus.ReachedTermination(self._commands, self._stop)

    def serve(self) -> dict:
        """Serve until the controller ends the session; its report. ScenarioMismatch if the
        controller runs another scenario or runs the link otherwise; StationLinkError if none
        comes, it sends no command, or it falls silent; the station's own errors are raised
        (after being sent to the controller)."""
        try:
            self._await(self._greeted, "hello")
            self._simulator.Initialize()
            self._apply_welds()
            self._await(self._commanded, "commands")
            self._simulator.set_target_realtime_rate(self._pace)
            self._simulator.ResetStatistics()
            self._clock.start(self._root.get_time())
            self._started_wall = time.monotonic()
            self._run()
        except ScenarioMismatch:
            raise  # the controller finds it in the hello just sent, and says it its own way
        except Exception as err:
            lines = str(err).strip().splitlines() or [type(err).__name__]
            stamp = wall_utime()
            publish(self._lcm, REPORT_CHANNEL, session_message(stamp, "error", lines[-1]))
            raise
        return self.report

    def _greeted(self) -> bool:
        """Answer each hello that came (a repeated one: the answer was lost); whether one
        came. ScenarioMismatch if it runs another scenario or the link otherwise."""
        hellos = [m for m in self._inbox.session if m.kind == HELLO]
        for message in hellos[self._hellos :]:
            text = identity_text(self._identity, self._pace)
            publish(self._lcm, REPORT_CHANNEL, session_message(wall_utime(), HELLO, text))
            check_hello(self._identity, self._pace, message)
        self._hellos = len(hellos)
        return self._hellos > 0

    def _commanded(self) -> bool:
        """Whether every command channel has spoken; meanwhile the measurements at time 0
        go out, so that the controller can start."""
        self._greeted()
        if all(self._inbox.count[c.channel] > 0 for c in COMMANDS):
            return True
        for publisher in self._publishers:
            publisher.ForcedPublish(publisher.GetMyContextFromRoot(self._root))
        return False

    def _await(self, ready, what: str) -> None:
        """Pump LCM until `ready()`; StationLinkError after `timeouts.start`."""
        limit, start = self._timeouts.start, time.monotonic()
        while not ready():
            self._inbox.raise_errors(session_errors=False)
            if time.monotonic() - start > limit:
                raise StationLinkError(self._absent(what, limit))
            self._lcm.HandleSubscriptions(int(WAITING_PUBLISH * 1000))

    def _absent(self, what: str, limit: float) -> str:
        url = self._lcm.get_lcm_url()
        if what == "hello":
            return (
                f"no controller came on {url} within {limit:g} s: run `hrc-drake simulate "
                f"--scenario S --station-lcm {shlex.quote(url)} --realtime`"
            )
        missing = [c.channel for c in COMMANDS if self._inbox.count[c.channel] == 0]
        return (
            f"the controller on {url} said hello but sent nothing on {', '.join(missing)} "
            f"within {limit:g} s"
        )

    def _run(self) -> None:
        while True:
            self._simulator.AdvanceTo(self._root.get_time() + 1.0)
            self._inbox.raise_errors(session_errors=False)
            if self._stop == "end":
                self._end()
                return
            if self._stop == "silent":
                channel, old = self._silent
                raise StationLinkError(
                    f"the controller stopped publishing on {self._lcm.get_lcm_url()}: nothing "
                    f"on {channel} for {old:.1f} s (the limit {SILENCE:g} s) at t = "
                    f"{self._root.get_time():.2f} s (it died or was stopped)"
                )
            self._apply_welds()
            self._greeted()

    def _apply_welds(self) -> None:
        hooks = self._hooks
        if hooks.welds_changed is not None and hooks.welds_changed(self._root):
            hooks.apply_welds(self._root)

    def _end(self) -> None:
        sim_time = self._root.get_time()
        wall = max(time.monotonic() - self._started_wall, 1e-9)
        late = np.round(np.percentile(self._lateness or [0], [50, 99, 100]) / 1e6, 4)
        lateness = dict(zip(("p50", "p99", "max"), late.tolist(), strict=True))
        report = {
            "sim_time": sim_time,
            "commands": self._inbox.count[ARM_COMMAND],
            "realtime": {
                "pace": self._pace,
                "pace_achieved": round(sim_time / wall, 4),
                # How far behind the wall clock the station ran [s]: what its readings' ages owe
                # to the simulation rather than to the trip.
                "lateness": lateness,
            },
        }
        if self._hooks.record is not None:
            report.update(self._hooks.record(self._root).to_json())
        self.report = report
        publish(self._lcm, REPORT_CHANNEL, session_message(wall_utime(), "report", report))


def serve_realtime_station(
    station,
    lcm: DrakeLcm,
    rates: dict[str, float],
    step: float,
    pace: float,
    timeouts: LockstepTimeouts | None = None,
    identity: ScenarioIdentity | None = None,
) -> dict:
    """Serve `station` (a `CellStation`, or a bare station diagram with the same ports) over
    `lcm` in real time at `pace` until the controller ends the session; the session's report.
    `rates`: the channels' (`channel_rates`); `step`: the plant's time step; `identity`: the
    scenario it serves, which the controller must run (`ScenarioMismatch` otherwise)."""
    simulated = {}
    if not isinstance(station, Diagram):
        simulated = {"hooks": cell_station_hooks(station), "owners": geometry_owners(station.plant)}
        station = station.diagram
    return RealtimeStationServer(
        station, lcm, rates, step, pace, timeouts=timeouts, identity=identity, **simulated
    ).serve()


__all__ = [
    "RealtimeCommands",
    "RealtimeStationServer",
    "initial_hold",
    "measured_at",
    "serve_realtime_station",
]
