"""The closed loop: a cell and its controller joined in one simulator, and its run.

A cell side is either the simulated station in this process (`LocalCell`) or a station served
elsewhere, reached through its LCM interface (`hrc_drake.cell.link.remote.RemoteCell`): the same
ports (`docs/station.md`), the same controller. A `Simulator` monitor watches the run: it ends it
when the Supervisor is done or has stopped, stops at the step where the station's welds change
(the loop applies them and goes on), watches the robot's contacts, lights the stack light and
takes the still. Unless the run is live, simulated time stands still while the planner works, so
that a run is the same whatever the machine does (same seed, same result); the robot's idle time
at a boundary is then one update of simulated time, and the wall-clock wait is reported apart
(`wall_idle`). Ctrl-C ends a run where it is: the recording and the report of what ran are still
written, marked interrupted.
"""

from __future__ import annotations

import contextlib
import io
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus

from hrc_drake.atomic import atomic_write_bytes, atomic_write_text
from hrc_drake.cell.controller.build import Controller, connect_controller
from hrc_drake.cell.controller.keep_clear import VIEW_TIMES
from hrc_drake.cell.controller.supervisor import Mode, SupervisorStatus
from hrc_drake.cell.ports import CellConfiguration
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.run.fault_report import fault_records
from hrc_drake.cell.run.result import RunResult
from hrc_drake.cell.run.safety_check import (
    SafetyCheck,
    SafetySample,
    SafetyTrace,
    check_separation,
)
from hrc_drake.cell.run.view import ForecastView, StackLight, frame_cell
from hrc_drake.cell.scenario import make_simulator
from hrc_drake.cell.scenario import plant_step as scenario_plant_step
from hrc_drake.cell.station.cell_station import CellStation
from hrc_drake.cell.station.contacts import Owner, geometry_owners, owner_pairs
from hrc_drake.cell.station.safety_function import SafetyFunctionLog
from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.pendant import UnlockButton
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.service import PlanService
from hrc_drake.progress import ProgressLine
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.scenario.safety import Separation
from hrc_drake.scenario.schema import Scenario
from hrc_drake.scenario.sensors import PORTS, sensor_models
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy

if TYPE_CHECKING:
    from hrc_drake.cell.link.realtime import RealtimeFigures


@dataclass
class Setup:
    """What a run is built from (`hrc_drake.cell.run.run.prepare_run`)."""

    scenario: Scenario
    space: StateSpace
    policy: Policy
    design: CellDesign
    options: MotionOptions
    plans: PlanService
    home: np.ndarray
    wait_for_planner: bool
    camera: bool = False  # the still camera is built (a still is asked for)


class CellSide(Protocol):
    """What the loop needs of the cell beside the station's ports."""

    diagram: Diagram
    meshcat: Meshcat | None

    def touching(self, root) -> Sequence[tuple[Owner, Owner]]:
        """The bodies in contact now (for the collision watch)."""

    def welds_changed(self, root, applied: frozenset) -> bool:
        """Whether the simulator must stop to apply welds (a simulated station only)."""

    def apply_welds(self, root) -> frozenset:
        """Apply the wanted welds; returns them."""

    def injected(self, root) -> tuple:
        """The faults the station has injected (`hrc_drake.cell.station.faults.Injection`, one per
        scenario fault; a station that does not say: none injected)."""

    def configuration(self, root) -> CellConfiguration:
        """The configuration the station measures now."""

    def camera_score(self, root) -> dict | None:
        """The camera's verdicts scored against the contact sensor's (the JSON of
        `hrc_drake.cell.station.camera_score.CameraScore`; None: no camera, or a station that
        does not say)."""

    def safety_function(self, root) -> SafetyFunctionLog | None:
        """What the station's safety function did (a station that does not say: None)."""

    def save_still(self, root, path: Path) -> None:
        """Save the camera's image (a simulated station only)."""

    def finish(self, root) -> None:
        """End the run on the cell's side."""

    def realtime(self) -> RealtimeFigures | None:
        """How the controller kept its pace over a real-time link (None: no such link)."""


class LocalCell:
    """The simulated station in this process, as the loop's cell side."""

    def __init__(self, station: CellStation):
        self.station, self.diagram, self.meshcat = station, station.diagram, station.meshcat
        self._owners = geometry_owners(station.plant)

    def touching(self, root):
        """The bodies in contact now, from the plant's contact results."""
        context = self.diagram.GetMyContextFromRoot(root)
        results = self.diagram.GetOutputPort("sim.contact_results").Eval(context)
        return owner_pairs(results, self._owners)

    def welds_changed(self, root, applied: frozenset) -> bool:
        """See `CellStation.welds_changed`."""
        return self.station.welds_changed(root, applied)

    def apply_welds(self, root) -> frozenset:
        """See `CellStation.apply_welds`."""
        return self.station.apply_welds(root)

    def injected(self, root) -> tuple:
        """The station's fault injector's record (its `sim.faults` output)."""
        context = self.diagram.GetMyContextFromRoot(root)
        return self.diagram.GetOutputPort("sim.faults").Eval(context)

    def configuration(self, root) -> CellConfiguration:
        """Where the parts are: the contact sensor's reading, the ground truth."""
        return self.station.configuration(root)

    def camera_score(self, root) -> dict | None:
        """The station's camera scored so far (None: no camera)."""
        score = self.station.camera_score(root)
        return None if score is None else score.to_json()

    def safety_function(self, root) -> SafetyFunctionLog | None:
        """The station's safety function's log (None: a station without the robot)."""
        state = self.station.safety_function_state(root)
        return None if state is None else state.log

    def save_still(self, root, path: Path) -> None:
        """The station camera's image, as PNG, written atomically."""
        import matplotlib.image

        context = self.diagram.GetMyContextFromRoot(root)
        image = self.diagram.GetOutputPort("sim.camera.rgb_image").Eval(context)
        buffer = io.BytesIO()
        matplotlib.image.imsave(buffer, np.array(image.data, copy=True)[:, :, :3], format="png")
        atomic_write_bytes(path, buffer.getvalue())

    def finish(self, root) -> None:
        """Nothing to end."""

    def realtime(self) -> None:
        """No link: none."""


class ClosedLoop:
    """A cell and its controller joined in one simulator, ready to run.

    `run()` simulates until the Supervisor is done or stopped (or the time is up, or Ctrl-C)
    and returns the RunResult; tests may instead `advance_to(t)` in steps and act on the
    simulation between them (`root_context`). `hrc_drake.cell.run.run.build_closed_loop` builds one
    from a scenario."""

    def __init__(
        self,
        setup: Setup,
        cell: CellSide,
        controller: Controller,
        still=None,
        pendant: UnlockButton | None = None,
    ):
        self.setup, self.cell, self.controller = setup, cell, controller
        self.pendant = pendant
        builder = DiagramBuilder()
        side = builder.AddNamedSystem("station", cell.diagram)
        brain = builder.AddNamedSystem("controller", controller.diagram)
        connect_controller(builder, side, brain)
        if pendant is not None:  # a person at the pendant: the station's `safety.unlock` is theirs
            pendant.connect(builder, side)
        for index in range(side.num_input_ports()):
            port = side.get_input_port(index)
            if port.get_name().startswith("sim."):
                builder.ExportInput(port, port.get_name())
        diagram = builder.Build()
        diagram.set_name("hrc_closed_loop")
        self.simulator = make_simulator(setup.scenario, diagram)
        self.watch = _Watch(
            _ContactWatch(),
            StackLight(cell.meshcat) if setup.scenario.body.enabled else None,
            (still[0], Path(still[1])) if still is not None else None,
        )
        if setup.scenario.body.enabled:
            self.watch.safety = _SafetySampler(self, setup.scenario.run.period)
        if cell.meshcat is not None and setup.scenario.safety.separation == Separation.PREDICTIVE:
            self.watch.forecast = ForecastView(cell.meshcat, len(VIEW_TIMES))
        self.simulator.set_monitor(_monitor(self))
        self._started = False

    @property
    def station(self) -> CellStation:
        """The simulated station (a local cell only)."""
        return self.cell.station

    @property
    def root_context(self):
        """The simulator's root context."""
        return self.simulator.get_mutable_context()

    @property
    def status(self) -> SupervisorStatus:
        """The Supervisor's status now."""
        diagram = self.controller.diagram
        context = diagram.GetMyContextFromRoot(self.simulator.get_context())
        return diagram.GetOutputPort("status").Eval(context)

    def start(self) -> None:
        """Initialize the simulation (once): events at time 0, the welds as the cell wants."""
        if not self._started:
            self._started = True
            self.simulator.Initialize()
            self.watch.welds = self.cell.apply_welds(self.root_context)

    def advance_to(self, t: float) -> Mode:
        """Simulate to time `t` (or until the Supervisor is done or stopped), applying the
        cell's welds as they change; the Supervisor's mode then."""
        self.start()
        while self.simulator.get_context().get_time() < t:
            self.simulator.AdvanceTo(t)
            mode = self.status.mode
            if mode in (Mode.DONE, Mode.FAILED):
                return mode
            self.watch.welds = self.cell.apply_welds(self.root_context)
        return self.status.mode

    def result(self) -> RunResult:
        """What the run did so far (after `advance_to`; no wall time measured: 0)."""
        return _result(self, 0.0, None, interrupted=False)

    def run(
        self, record=None, live: bool = False, progress: bool = False, pace: float | None = None
    ) -> RunResult:
        """Simulate to the end (see the class docstring); with `record`, save the Meshcat
        recording there; `live` paces the run to the wall clock, `pace` at that real-time rate
        (a station over the real-time link)."""
        meshcat = self.cell.meshcat
        if meshcat is not None:
            frame_cell(meshcat, self.station.frames)
        if record is not None:
            self.station.visualizer.StartRecording()
        if live or pace is not None:
            self.simulator.set_target_realtime_rate(1.0 if pace is None else pace)
        if live:
            _announce_live(meshcat)
        start = time.perf_counter()
        try:
            finished = self._run_to_end(progress)
        finally:
            if self.pendant is not None:
                self.pendant.close()
        wall = time.perf_counter() - start
        self.cell.finish(self.simulator.get_context())
        path = None
        if record is not None:
            with _ctrl_c_ignored():  # a second Ctrl-C does not cut the recording short
                self.station.visualizer.StopRecording()
                self.station.visualizer.PublishRecording()
                path = Path(atomic_write_text(record, meshcat.StaticHtml()))
        return _result(self, wall, path, interrupted=not finished)

    def _run_to_end(self, progress: bool) -> bool:
        """Simulate until the end, in 1 s pieces; False if Ctrl-C ended it first."""
        limit = self.setup.scenario.run.max_sim_time
        clock = self.simulator.get_context()
        with ProgressLine(f"cell {self.setup.scenario.name}", "sim s", interval=2.0) as bar:
            try:
                self.start()
                while clock.get_time() < limit:
                    mode = self.advance_to(min(limit, clock.get_time() + 1.0))
                    if mode in (Mode.DONE, Mode.FAILED):
                        break
                    if progress:
                        bar.update(round(clock.get_time(), 1), 0, float(self.status.step))
            except KeyboardInterrupt:
                return False
        return True


class _ContactWatch:
    """Flags contacts of the robot with anything but the part its fingers handle."""

    def __init__(self, station: CellStation | None = None):
        self._owner = geometry_owners(station.plant) if station is not None else {}
        self.collisions: list[str] = []

    def check(self, pairs, handled: str | None, now: float) -> None:
        """Note the robot's contacts among the touching `pairs` (by owner) at `now`
        (`handled`: the part it moves)."""
        for first, second in pairs:
            robot_first = first.model in (UR3, GRIPPER)
            if not (robot_first or second.model in (UR3, GRIPPER)):
                continue
            robot, other = (first, second) if robot_first else (second, first)
            if robot.body.endswith("finger") and handled is not None and other.model == handled:
                continue
            text = f"{first.model}::{first.body} touches {second.model}::{second.body}"
            if not self.collisions or self.collisions[-1].split(": ", 1)[1] != text:
                self.collisions.append(f"{now:.2f} s: {text}")


@dataclass
class _Watch:
    """What the loop's monitor keeps between calls."""

    contacts: _ContactWatch
    lights: StackLight | None
    still: tuple[float, Path] | None
    next_check: float = 0.0
    welds: frozenset = frozenset()  # the welds applied last
    forecast: ForecastView | None = None
    safety: _SafetySampler | None = None  # the samples the run's own safety check reads


class _SafetySampler:
    """Takes the safety check's samples (`hrc_drake.cell.run.safety_check`) from the cell's
    measured ports and the arm's command, once per monitor period."""

    def __init__(self, loop: ClosedLoop, period: float):
        self.trace = SafetyTrace(period)
        self._cell, self._controller = loop.cell.diagram, loop.controller.diagram
        # The part held: of the configuration the controller also reads (computed once for
        # both), or under a camera the contact sensor's (cheaper than the exact reading).
        camera = self._cell.HasOutputPort("sim.configuration")
        held = camera and self._cell.HasOutputPort("sim.held_part")
        self._held = self._cell.GetOutputPort("sim.held_part") if held else None
        self._arm, self._opening, self._body, self._configuration = (
            self._truth(name)
            for name in (
                "ur3.state_estimated",
                "rg2.state_measured",
                "operator.body",
                "configuration",
            )
        )
        self._commanded = self._controller.GetOutputPort("ur3.velocity")

    def sample(self, root, now: float) -> None:
        """Take a sample if one is due at `now`."""
        if not self.trace.due(now):
            return
        cell = self._cell.GetMyContextFromRoot(root)
        arm = self._arm.Eval(cell)
        controller = self._controller.GetMyContextFromRoot(root)
        commanded = self._commanded.Eval(controller)
        n = len(commanded)
        self.trace.add(
            SafetySample(
                time=now,
                q=np.array(arm[:n]),
                v=np.array(arm[n:]),
                commanded=np.array(commanded),
                opening=float(self._opening.Eval(cell)[0]),
                carrying=self._carrying(cell),
                body=self._body.Eval(cell),
            )
        )

    def _carrying(self, cell) -> str | None:
        """The part in the gripper: the held part of the cell's configuration, or the
        contact sensor's `sim.held_part` where a camera reads the configuration."""
        if self._held is not None:
            return self._held.Eval(cell) or None
        return self._configuration.Eval(cell).held()

    def _truth(self, name: str):
        """The cell's port `name`, or its exact value `sim.<name>` where a sensor model
        (`sensors:`) sits on it: the check scores what happened, not what was measured."""
        exact = f"sim.{name}"
        return self._cell.GetOutputPort(exact if self._cell.HasOutputPort(exact) else name)


def _monitor(loop: ClosedLoop):
    """The Simulator monitor of a run (see the module docstring)."""
    setup, cell, watch = loop.setup, loop.cell, loop.watch
    root = loop.simulator.get_context()
    status_port = loop.controller.diagram.GetOutputPort("status")
    controller_context = loop.controller.diagram.GetMyContextFromRoot(root)
    period = setup.scenario.run.period
    plant_step = scenario_plant_step(setup.scenario)
    waits = setup.wait_for_planner

    def monitor(context) -> EventStatus:
        now = context.get_time()
        if not (_on_the_period(now, period) or _on_the_period(now, plant_step)):
            # A step that ends between the plant's steps and the controller's updates (a
            # sensor's sample at its own rate, `sensors:`): neither the plant nor the
            # controller has changed since, so there is nothing new to watch.
            return EventStatus.DidNothing()
        status: SupervisorStatus = status_port.Eval(controller_context)
        if now >= watch.next_check:
            watch.next_check = now + period
            handled = status.task.part if status.task else None
            watch.contacts.check(cell.touching(context), handled or None, now)
        if watch.safety is not None:
            watch.safety.sample(context, now)
        if watch.lights is not None:
            watch.lights.show(status, now)
        if watch.forecast is not None:
            watch.forecast.show(status, now)
        if watch.still is not None and now >= watch.still[0]:
            cell.save_still(context, watch.still[1])
            watch.still = None
        if status.mode in (Mode.DONE, Mode.FAILED):
            return EventStatus.ReachedTermination(loop.controller.supervisor, status.mode.value)
        if waits and status.mode == Mode.ASK:
            # Simulated time stands still while the planner works (the controller's update
            # itself never waits): a run does not depend on how fast the machine plans. At a
            # boundary the plans asked ahead are done, so whether the indicated task's plan
            # was ready depends on what was predicted, not on the machine.
            setup.plans.wait_all()
        if waits and status.mode == Mode.PLAN:
            setup.plans.wait(status.ask.request)
        if cell.welds_changed(context, watch.welds):
            return EventStatus.ReachedTermination(loop.controller.supervisor, "welds")
        return EventStatus.DidNothing()

    return monitor


def _on_the_period(now: float, period: float) -> bool:
    """Whether `now` is one of the run's update times, a whole number of `period`s (event
    times are sums of floats: within a microsecond)."""
    return abs(now - round(now / period) * period) < 1e-6


def _announce_live(meshcat: Meshcat) -> None:
    """Tell the person in the terminal where the page and its buttons are (on stderr: stdout
    is kept for `--json`)."""
    from hrc_drake.hri.live import live_banner

    print(live_banner(meshcat.web_url()), file=sys.stderr, flush=True)


@contextlib.contextmanager
def _ctrl_c_ignored():
    """Ctrl-C (SIGINT) is ignored inside; in the main thread only (elsewhere Python has no
    signal handler to change)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _safety_check(loop: ClosedLoop) -> SafetyCheck | None:
    """The run's own check of separation over its samples (None without a body)."""
    sampler = loop.watch.safety
    if sampler is None:
        return None
    setup = loop.setup
    config = setup.scenario.safety
    # T_r is the robot's reaction and the sensors' response both: a tracker under `sensors:`
    # reports the body up to a period and its latency bound late; the safety sensor, which
    # the safety function reads, up to its slowest unit's response time.
    body = sensor_models(setup.scenario.sensors).get(PORTS["body"])
    response = 0.0 if body is None else body.stale_after
    if config.sensor.enabled:
        response = max(response, config.sensor.response_time)
    return check_separation(
        sampler.trace.samples,
        RobotEnvelope(setup.design),
        replace(config, reaction_time=config.reaction_time + response),
        setup.options.joint_acceleration_limit,
    )


def _result(loop: ClosedLoop, wall: float, path, interrupted: bool) -> RunResult:
    setup, watch = loop.setup, loop.watch
    root, space, status = loop.simulator.get_context(), setup.space, loop.status
    try:
        final_index = space.index(status.state)
        final_kind = space.state_kind(final_index).key
        terminal = bool(space.kind[final_index] == StateKind.TERMINAL)
    except KeyError:
        final_kind, terminal = "unknown", False
    error = status.error
    if interrupted:
        error = f"interrupted at {root.get_time():.2f} s of simulated time (Ctrl-C)"
    elif status.mode not in (Mode.DONE, Mode.FAILED):
        error = f"no terminal state within {setup.scenario.run.max_sim_time} s of simulated time"
    states = status.visited
    return RunResult(
        scenario=setup.scenario.name,
        states=states,
        names=[space.name(space.index(s)) for s in states],
        tasks=list(status.history),
        final_tokens=loop.cell.configuration(root).tokens(),
        final_kind=final_kind,
        done=status.mode == Mode.DONE and terminal,
        error=error,
        collisions=watch.contacts.collisions,
        sim_time=root.get_time(),
        wall_time=wall,
        recording=path,
        events=status.events,
        safety=loop.controller.safety_log(root),
        safety_check=_safety_check(loop),
        safety_function=loop.cell.safety_function(root),
        speed_changes=tuple(watch.lights.changes) if watch.lights is not None else (),
        interrupted=interrupted,
        interaction=setup.scenario.interaction.mode,
        separation=setup.scenario.safety.separation,
        waited=status.clock.waited,
        replans=status.clear.replans,
        capped=status.capped,
        camera=loop.cell.camera_score(root),
        faults=tuple(
            fault_records(
                setup.scenario.faults, loop.cell.injected(root), status.detections, root.get_time()
            )
        ),
        realtime=loop.cell.realtime(),
    )


__all__ = ["CellSide", "ClosedLoop", "LocalCell", "Setup"]
