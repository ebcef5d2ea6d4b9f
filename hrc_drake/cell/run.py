"""Closed-loop runs of the cell: the station, the Supervisor, an operator, and a recording.

`run_scenario` builds the whole diagram from one scenario (the cell station generated from the
assembly spec and its layout, the Supervisor wired to the SlotMonitor and the controller inputs),
checks before simulating that the UR3 reaches every grasp the spec needs, and simulates until
the Supervisor reports done or failed. A `Simulator` monitor does what a system cannot: it stops
the simulation at the step where the Supervisor's wanted weld constraints (grasp, bolt) change
so they are applied at once, watches the contact results for robot collisions, and ends the run
when the Supervisor does. `hrc-drake simulate` is its command line.
"""

from __future__ import annotations

import contextlib
import io
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus

from hrc_drake.atomic import atomic_write_bytes
from hrc_drake.cell.builder import CellScenario, CellStation, build_cell, save_meshcat_html
from hrc_drake.cell.safety import SafetyLog, SeparationMonitor
from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options, plant_config
from hrc_drake.cell.supervisor import Mode, Planner, Supervisor, SupervisorStatus, TaskRecord, Weld
from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.scenario import Scenario
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.planner import MotionPlanner, check_reach
from hrc_drake.progress import ProgressLine
from hrc_drake.robot_models import RG2_MAX_OPENING
from hrc_drake.tasks.decide import Operator
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.policy import Policy, load_policy
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

ROBOT_INSTANCES = ("ur3", "rg2")


@dataclass(frozen=True)
class RunResult:
    """What a closed-loop run did, read from the diagram's outputs."""

    scenario: str
    states: list[tuple[str, ...]]
    names: list[str]
    tasks: list[TaskRecord]
    final_tokens: frozenset[str]
    final_kind: str
    done: bool
    error: str | None
    collisions: list[str]
    sim_time: float
    wall_time: float
    recording: Path | None = None
    events: tuple[str, ...] = field(default_factory=tuple)
    idle: tuple[float, ...] = ()
    """Per task: wall seconds the robot waited on the planner after the operator's answer."""
    plan_ready: tuple[bool, ...] = ()
    """Per task: the plan was ready (planned ahead) when the operator answered."""
    safety: SafetyLog | None = None
    """Separation monitoring figures (None: the scenario has no operator body)."""
    speed_changes: tuple[tuple[float, str], ...] = ()
    """(simulated time, "moving" | "slowed" | "stopped") each time the robot's speed state
    changes (with the operator body)."""

    @property
    def real_time_factor(self) -> float | None:
        """Simulated time over wall time."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else None

    def _idle_per_task(self) -> list[float]:
        return [*self.idle, *[0.0] * (len(self.tasks) - len(self.idle))][: len(self.tasks)]

    def _ready_per_task(self) -> list[bool]:
        missing = len(self.tasks) - len(self.plan_ready)
        return [*self.plan_ready, *[False] * missing][: len(self.tasks)]

    def to_json(self) -> dict:
        """A JSON-able summary (the `--json` of `hrc-drake simulate`)."""
        rtf = self.real_time_factor
        return {
            "scenario": self.scenario,
            "states": [list(s) for s in self.states],
            "names": self.names,
            "terminal": bool(self.done),
            "final_kind": self.final_kind,
            "final_configuration": sorted(self.final_tokens),
            "collisions": len(self.collisions),
            "contacts": list(self.collisions),
            "steps": [
                {
                    "step": t.step,
                    "proposed": t.proposed,
                    "operator": t.indicated,
                    "observed": t.observed,
                    "part": t.part,
                    "sim_time": round(t.end_time - t.start_time, 3),
                    "idle_time": round(idle, 4),
                    "plan_ready": ready,
                }
                for t, idle, ready in zip(
                    self.tasks, self._idle_per_task(), self._ready_per_task(), strict=True
                )
            ],
            "mean_idle": round(float(np.mean(self.idle)), 4) if self.idle else 0.0,
            "error": self.error,
            "sim_time": round(self.sim_time, 3),
            "wall_time": round(self.wall_time, 3),
            "real_time_factor": None if rtf is None else round(rtf, 3),
            "recording": str(self.recording) if self.recording else None,
            "safety": self.safety.to_json() if self.safety is not None else None,
        }


_PLANNERS: dict[tuple, MotionPlanner] = {}


def shared_planner(options: MotionOptions, design: CellDesign | None = None) -> MotionPlanner:
    """One planner (and its plan cache) per cell and set of options, shared by a process's runs.

    A new one is checked for reach (`check_reach`) before it is handed out."""
    design = design if design is not None else CellDesign.of(load_spec())
    key = (options, design.key())
    if key not in _PLANNERS:
        planner = MotionPlanner(options, design=design)
        check_reach(planner)
        _PLANNERS[key] = planner
    return _PLANNERS[key]


class _ContactWatch:
    """Flags contacts of the robot with anything but the part it is handling."""

    def __init__(self, station: CellStation):
        plant = station.plant
        self._owner = {}
        for body_index in range(plant.num_bodies()):
            body = plant.get_body(BodyIndex(body_index))
            model = plant.GetModelInstanceName(body.model_instance())
            for gid in plant.GetCollisionGeometriesForBody(body):
                self._owner[gid] = (model, body.name())
        self.collisions: list[str] = []

    def check(self, results, handled: str | None, now: float) -> None:
        pairs = [
            (
                results.point_pair_contact_info(i).point_pair().id_A,
                results.point_pair_contact_info(i).point_pair().id_B,
            )
            for i in range(results.num_point_pair_contacts())
        ]
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            pairs.append((surface.id_M(), surface.id_N()))
        for a, b in pairs:
            (ma, ba), (mb, bb) = self._owner.get(a, ("?", "?")), self._owner.get(b, ("?", "?"))
            robot_a, robot_b = ma in ROBOT_INSTANCES, mb in ROBOT_INSTANCES
            if not (robot_a or robot_b):
                continue
            other = mb if robot_a else ma
            finger = (ba if robot_a else bb).endswith("finger")
            if finger and handled is not None and other == handled:
                continue
            text = f"{now:.2f} s: {ma}::{ba} touches {mb}::{bb}"
            if (
                not self.collisions
                or self.collisions[-1].split(": ", 1)[1] != text.split(": ", 1)[1]
            ):
                self.collisions.append(text)


def scenario_policy(scenario: Scenario, space) -> Policy:
    """The scenario's policy file, or the exact minimum-effort policy."""
    if scenario.policy:
        return load_policy(scenario.policy, space)
    return exact_policy(space)


def run_scenario(
    scenario: Scenario | str,
    policy: Policy | None = None,
    record: str | Path | None = None,
    progress: bool = False,
    planner: Planner | None = None,
    still: tuple[float, str | Path] | None = None,
    scenario_text: str | None = None,
    operator: Operator | None = None,
    body_script=None,
    live: bool = False,
    on_prompt=None,
    on_task=None,
    motion_planner: MotionPlanner | None = None,
) -> RunResult:
    """Run one scenario through the full cell diagram until a terminal state (or a failure).

    `scenario` is a Scenario or a scenario name/path (then `scenario_text` overrides apply).
    `policy` replaces the scenario's. `planner` replaces the motion layer's `plan_task` (tests
    use it to misplace a part). `still=(t, path)` saves a camera image at simulated time t.
    `operator` (a callable `(step, state, proposal) -> task`) replaces the scenario's.
    `body_script` replaces the operator body's (`hrc_drake.cell.operator_body.BodyScript`).
    `live`: a person is the operator, through Meshcat buttons (`hrc_drake.hri.live`); the run
    serves Meshcat, prints its URL and paces itself to the wall clock; `on_prompt` is handed to
    the `LiveOperator` (tests inject clicks from it). `on_task(record)` hears every task as the
    cell observed it (a `TaskRecord`). `motion_planner` replaces the process's shared planner
    (`shared_planner`), e.g. a fresh one so that a run does not use plans cached by others.
    While the operator bolts, the run plans the tasks the policy predicts next: its
    `predicted_tasks(state)` (most likely first) if it has one, else its `next_task(state)`.
    CellModelError (before any simulation) if the spec does not fit the cell."""
    if not isinstance(scenario, Scenario):
        scenario = load_cell_scenario(scenario, scenario_text)
    space = generate_states(load_spec(scenario.assembly_path))
    policy = policy or scenario_policy(scenario, space)
    policy.matches(space.spec)
    design = cell_design(scenario, space.spec)
    options = motion_options(scenario)
    if motion_planner is None:
        motion = shared_planner(options, design)
    else:
        motion = motion_planner
        check_reach(motion)
    home_opening = RG2_MAX_OPENING * 0.8
    with_body = scenario.body.enabled

    station = build_cell(
        CellScenario(
            design=design,
            plant_config=plant_config(scenario),
            meshcat=record is not None or live,
            ur3_initial_positions=[float(x) for x in motion.q_home],
            rg2_initial_opening=home_opening,
            hydroelastic_modulus=scenario.physics.hydroelastic_modulus,
            mesh_resolution_hint=scenario.physics.mesh_resolution_hint,
            camera=still is not None,
            operator_body=scenario.body if with_body else None,
            operator_script=body_script,
        )
    )
    builder = DiagramBuilder()
    cell = builder.AddNamedSystem("cell", station.diagram)

    idle: list[float] = []
    ready: list[bool] = []

    def plan(configuration, task, last, layout):
        # Simulated time stands still while the planner works: its wall time is what a real
        # robot would stand idle between the operator's answer and its first motion.
        ready.append(motion.has_plan(configuration, task, last_token=last, layout=layout))
        start = time.perf_counter()
        result = motion.plan_task(configuration, task, last_token=last, layout=layout)
        idle.append(time.perf_counter() - start)
        return result

    def chosen_planner(configuration, task, last, layout):
        if planner is None:
            return plan(configuration, task, last, layout)
        idle.append(0.0)
        ready.append(False)
        return planner(configuration, task, last, layout)

    run = scenario.run
    simulator_cell: list[Simulator] = []
    if live:
        operator = _live_operator(station, space, simulator_cell, on_prompt)
    supervisor = builder.AddNamedSystem(
        "supervisor",
        Supervisor(
            space,
            policy,
            operator or scenario.operator_for(space),
            chosen_planner,
            home=motion.q_home,
            home_opening=home_opening,
            period=run.period,
            settle_time=run.settle_time,
            max_steps=run.max_steps,
            joint_acceleration=options.joint_acceleration_limit,
            on_task=on_task,
        ),
    )
    builder.Connect(
        cell.GetOutputPort("slot_configuration"), supervisor.GetInputPort("slot_configuration")
    )
    builder.Connect(
        supervisor.GetOutputPort("ur3.desired_state"), cell.GetInputPort("ur3.desired_state")
    )
    builder.Connect(
        supervisor.GetOutputPort("rg2.desired_opening"), cell.GetInputPort("rg2.desired_opening")
    )
    separation = None
    if with_body:
        separation = builder.AddNamedSystem(
            "separation_monitor",
            SeparationMonitor(
                station.plant,
                station.scene_graph,
                [station.instances["ur3"], station.instances["rg2"]],
                {name: station.instances[name] for name in design.instance_names},
                scenario.safety,
                options.joint_acceleration_limit,
                run.period,
            ),
        )
        status_out = supervisor.GetOutputPort("status")
        builder.Connect(status_out, cell.GetInputPort("operator.status"))
        builder.Connect(status_out, separation.GetInputPort("status"))
        builder.Connect(cell.GetOutputPort("plant_state"), separation.GetInputPort("plant_state"))
        builder.Connect(cell.GetOutputPort("query_object"), separation.GetInputPort("query_object"))
        builder.Connect(cell.GetOutputPort("operator.spheres"), separation.GetInputPort("body"))
        builder.Connect(
            separation.GetOutputPort("speed_limit"), supervisor.GetInputPort("speed_limit")
        )
    diagram = builder.Build()
    diagram.set_name("hrc_closed_loop")

    simulator = Simulator(diagram)
    simulator_cell.append(simulator)
    root = simulator.get_mutable_context()
    lights = _StackLight(station.meshcat) if with_body else None
    plant = station.plant
    plant_context = plant.GetMyMutableContextFromRoot(root)
    station_context = station.diagram.GetMyContextFromRoot(root)
    station.deactivate_constraints(plant_context)
    supervisor_context = supervisor.GetMyContextFromRoot(root)
    status_port = supervisor.GetOutputPort("status")
    contacts = station.diagram.GetOutputPort("contact_results")
    watch = _ContactWatch(station)
    active: set = set()
    pending_still = [still]
    next_watch = [0.0]
    planned_ahead: set[int] = set()
    predict = getattr(policy, "predicted_tasks", None)

    def predicted_tasks(state: tuple[str, ...]) -> list[str]:
        tasks = predict(state) if predict is not None else [policy.next_task(state)]
        return [t for t in tasks if t is not None]

    def plan_ahead(status: SupervisorStatus, now: float) -> None:
        """During the hold, plan what the policy will propose once this task is done."""
        plan_now = status.plan
        step = status.step
        if step in planned_ahead or status.plan_time(now) < plan_now.t_in_place:
            return
        planned_ahead.add(step)
        _proposed, indicated, part = status.pending
        layout = station.configuration(station_context).layout()
        if indicated == UNDO:
            layout.pop(part, None)
            state = status.state[:-1]
        else:
            layout[part] = indicated
            state = (*status.state, indicated)
        try:
            index = space.index(state)
        except KeyError:
            return
        if space.kind[index] == StateKind.TERMINAL:
            return
        last = state[-1] if state else None
        for task in predicted_tasks(state):
            _plan_ahead_quietly(motion, frozenset(layout.values()), task, last, layout)

    def constraint(weld: Weld):
        if weld.kind == "grasp":
            return station.grasp_constraints[weld.part]
        return station.bolt_constraints[(weld.part, weld.seat)]

    def monitor(context) -> EventStatus:
        now = context.get_time()
        status: SupervisorStatus = status_port.Eval(supervisor_context)
        if now >= next_watch[0]:
            next_watch[0] = now + run.period
            handled = status.pending[2] if status.pending else None
            watch.check(contacts.Eval(station_context), handled, now)
        if lights is not None:
            lights.show(status, now)
        if run.plan_ahead and planner is None and status.mode == Mode.EXECUTE and status.plan:
            plan_ahead(status, now)
        if pending_still[0] is not None and now >= pending_still[0][0]:
            _save_still(station, station_context, Path(pending_still[0][1]))
            pending_still[0] = None
        if status.mode in (Mode.DONE, Mode.FAILED):
            return EventStatus.ReachedTermination(supervisor, status.mode.value)
        if {constraint(w) for w in status.welds} != active:
            return EventStatus.ReachedTermination(supervisor, "welds")
        return EventStatus.DidNothing()

    simulator.set_monitor(monitor)
    if run.plan_ahead and planner is None:
        # The robot's first proposal is planned before the operator answers.
        for first in predicted_tasks(()):
            if first != UNDO:
                _plan_ahead_quietly(motion, frozenset(), first, None, {})
    if record is not None:
        station.visualizer.StartRecording()
    if live:
        simulator.set_target_realtime_rate(1.0)
        print(f"live: open {station.meshcat.web_url()} in a web browser", flush=True)
    start = time.perf_counter()
    simulator.Initialize()
    status: SupervisorStatus = status_port.Eval(supervisor_context)
    with ProgressLine(f"cell {scenario.name}", "sim s", interval=2.0) as bar:
        while root.get_time() < run.max_sim_time:
            simulator.AdvanceTo(run.max_sim_time)
            status = status_port.Eval(supervisor_context)
            if status.mode in (Mode.DONE, Mode.FAILED):
                break
            wanted = {constraint(w) for w in status.welds}
            for cid in wanted ^ active:
                plant.SetConstraintActiveStatus(plant_context, cid, cid in wanted)
            active = wanted
            if progress:
                bar.update(round(root.get_time(), 1), 0, float(status.step))
    wall = time.perf_counter() - start
    path = None
    if record is not None:
        station.visualizer.StopRecording()
        station.visualizer.PublishRecording()
        path = save_meshcat_html(station.meshcat, record)
    final_tokens = (
        station.diagram.GetOutputPort("slot_configuration").Eval(station_context).tokens()
    )
    try:
        final_index = space.index(status.state)
        final_kind = space.state_kind(final_index).key
        terminal = bool(space.kind[final_index] == StateKind.TERMINAL)
    except KeyError:
        final_kind, terminal = "unknown", False
    if status.mode not in (Mode.DONE, Mode.FAILED):
        error = f"no terminal state within {run.max_sim_time} s of simulated time"
    else:
        error = status.error
    states = status.visited
    return RunResult(
        scenario=scenario.name,
        states=states,
        names=[space.name(space.index(s)) for s in states],
        tasks=list(status.history),
        final_tokens=final_tokens,
        final_kind=final_kind,
        done=status.mode == Mode.DONE and terminal,
        error=error,
        collisions=watch.collisions,
        sim_time=root.get_time(),
        wall_time=wall,
        recording=path,
        events=status.events,
        idle=tuple(idle),
        plan_ready=tuple(ready),
        safety=separation.log(separation.GetMyContextFromRoot(root)) if separation else None,
        speed_changes=tuple(lights.changes) if lights is not None else (),
    )


_LAMPS = {"moving": (0.1, 0.8, 0.2), "slowed": (1.0, 0.7, 0.0), "stopped": (0.9, 0.1, 0.1)}


class _StackLight:
    """The speed the separation monitor allows over time (`changes`), and with Meshcat a stack
    light beside the robot (also in recordings): green for the plan's own speed, amber while the
    monitor slows the robot, red while it stops it."""

    def __init__(self, meshcat):
        from pydrake.geometry import Cylinder, Rgba, Sphere
        from pydrake.math import RigidTransform

        self.meshcat, self.state = meshcat, None
        self.changes: list[tuple[float, str]] = []
        if meshcat is None:
            return
        meshcat.SetObject("/safety/pole", Cylinder(0.008, 0.3), Rgba(0.3, 0.3, 0.3, 1.0))
        meshcat.SetTransform("/safety/pole", RigidTransform([-0.15, 0.25, 0.15]))
        for k, (name, rgb) in enumerate(_LAMPS.items()):
            meshcat.SetObject(f"/safety/{name}", Sphere(0.025), Rgba(*rgb, 1.0))
            meshcat.SetTransform(f"/safety/{name}", RigidTransform([-0.15, 0.25, 0.32 + 0.055 * k]))
            meshcat.SetProperty(f"/safety/{name}", "visible", False, 0.0)

    def show(self, status: SupervisorStatus, now: float) -> None:
        """Light the lamp of the robot's state at `now` (recorded at that time)."""
        # The speed the monitor allows, also during the hold (a monitored stop: red while the
        # person is within S_p of the still robot).
        state = "moving"
        if status.speed < 1.0 - 1e-9:
            state = "stopped" if status.speed <= 1e-9 else "slowed"
        if state == self.state:
            return
        self.state = state
        self.changes.append((round(now, 3), state))
        if self.meshcat is None:
            return
        for name in _LAMPS:
            self.meshcat.SetProperty(f"/safety/{name}", "visible", name == state, now)


def _live_operator(station: CellStation, space, simulator_cell: list, on_prompt):
    """A LiveOperator on the station's Meshcat; after each answer the real-time pacing starts
    afresh, so that the simulation does not race to catch up the time the person took."""
    from hrc_drake.hri.live import LiveOperator
    from hrc_drake.motion.poses import part_pose

    def place(task, state):
        try:
            return part_pose(station.frames, task, list(state))
        except (KeyError, ValueError):
            return None

    def clock() -> float:
        return simulator_cell[0].get_context().get_time() if simulator_cell else 0.0

    def after_answer() -> None:
        if simulator_cell:
            simulator_cell[0].ResetStatistics()

    return LiveOperator(station.meshcat, space, place, clock, on_prompt, after_answer)


def _plan_ahead_quietly(motion: MotionPlanner, configuration, task, last, layout) -> None:
    """Fill the plan cache ahead of a boundary; a failure is left for the boundary to report."""
    with contextlib.suppress(RuntimeError, ValueError):
        motion.plan_task(configuration, task, last_token=last, layout=layout)


def _save_still(station: CellStation, station_context, path: Path) -> None:
    import matplotlib.image

    image = station.diagram.GetOutputPort("camera.rgb_image").Eval(station_context)
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, np.array(image.data, copy=True)[:, :, :3], format="png")
    atomic_write_bytes(path, buffer.getvalue())


__all__ = ["RunResult", "run_scenario", "scenario_policy", "shared_planner"]
