"""Closed-loop runs of the cell: the station, the Supervisor, an operator, and a recording.

`run_scenario` builds the diagram (the cell station as a subsystem, the Supervisor wired to its
SlotMonitor and controller inputs), simulates until the Supervisor reports a terminal state,
applies the weld constraints the Supervisor asks for (grasp, bolt) between simulation steps, and
watches the contact results for robot collisions. `hrc-drake simulate` is its command line.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell.builder import CellScenario, CellStation, build_cell, save_meshcat_html
from hrc_drake.cell.supervisor import (
    Mode,
    Planner,
    Supervisor,
    SupervisorStatus,
    TaskRecord,
    Weld,
)
from hrc_drake.hri.scenario import OperatorScenario, load_scenario
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.progress import ProgressLine
from hrc_drake.robot_models import RG2_MAX_OPENING
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.policy import Policy, load_policy
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import load_spec

ROBOT_INSTANCES = ("ur3", "rg2")


@dataclass(frozen=True)
class RunSettings:
    """Physics and timing of a closed-loop run.

    `full()` is the product setting (5 s bolting holds, 0.25 m/s collaborative TCP speed);
    `lean()` keeps the same models and limits but bolts in 0.5 s, for tests and previews.
    """

    time_step: float = 5e-3
    hold_time: float = 5.0
    tcp_speed_limit: float = 0.25
    mesh_resolution_hint: float | None = None
    period: float = 0.02
    settle_time: float = 0.3
    max_sim_time: float = 900.0

    @staticmethod
    def full() -> RunSettings:
        """The product settings."""
        return RunSettings()

    @staticmethod
    def lean() -> RunSettings:
        """Short bolting holds, same physics and limits: for tests and quick previews."""
        return RunSettings(hold_time=0.5, settle_time=0.2)

    def motion_options(self) -> MotionOptions:
        """The motion-layer options these settings imply."""
        return MotionOptions(hold_time=self.hold_time, tcp_speed_limit=self.tcp_speed_limit)


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

    def to_json(self) -> dict:
        """A JSON-able summary."""
        return {
            "scenario": self.scenario,
            "states": [list(s) for s in self.states],
            "names": self.names,
            "tasks": [
                {
                    "step": t.step,
                    "proposed": t.proposed,
                    "indicated": t.indicated,
                    "observed": t.observed,
                    "part": t.part,
                    "sim_time": round(t.end_time - t.start_time, 3),
                }
                for t in self.tasks
            ],
            "final_configuration": sorted(self.final_tokens),
            "final_kind": self.final_kind,
            "done": self.done,
            "error": self.error,
            "collisions": self.collisions,
            "sim_time": round(self.sim_time, 3),
            "wall_time": round(self.wall_time, 3),
            "real_time_factor": round(self.sim_time / self.wall_time, 3)
            if self.wall_time
            else None,
            "recording": str(self.recording) if self.recording else None,
        }


_PLANNERS: dict[MotionOptions, MotionPlanner] = {}


def shared_planner(options: MotionOptions) -> MotionPlanner:
    """One planner (and its plan cache) per set of options, shared by the runs of a process."""
    if options not in _PLANNERS:
        _PLANNERS[options] = MotionPlanner(options)
    return _PLANNERS[options]


class _ContactWatch:
    """Flags contacts of the robot with anything but the part it is handling."""

    def __init__(self, station: CellStation):
        plant, inspector = station.plant, station.scene_graph.model_inspector()
        self._owner = {}
        for body_index in range(plant.num_bodies()):
            body = plant.get_body(BodyIndex(body_index))
            model = plant.GetModelInstanceName(body.model_instance())
            for gid in plant.GetCollisionGeometriesForBody(body):
                self._owner[gid] = (model, body.name())
        self._inspector = inspector
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


def run_scenario(
    scenario: OperatorScenario | str,
    policy: Policy | None = None,
    settings: RunSettings | None = None,
    record: str | Path | None = None,
    progress: bool = False,
    planner: Planner | None = None,
    still: tuple[float, str | Path] | None = None,
) -> RunResult:
    """Run one operator scenario through the full cell diagram until a terminal state.

    `planner` replaces the motion layer's `plan_task` (tests use it to misplace a part).
    `still=(t, path)` saves a camera image of the cell at simulated time t as a PNG."""
    scenario = load_scenario(scenario) if isinstance(scenario, str) else scenario
    settings = settings or RunSettings.lean()
    space = generate_states(load_spec(scenario.assembly))
    policy = policy or exact_policy(space)
    policy.matches(space.spec)
    motion = shared_planner(settings.motion_options())
    home_opening = RG2_MAX_OPENING * 0.8

    plant_config = MultibodyPlantConfig(
        time_step=settings.time_step,
        contact_model="hydroelastic_with_fallback",
        discrete_contact_approximation="sap",
        contact_surface_representation="polygon",
    )
    station = build_cell(
        CellScenario(
            plant_config=plant_config,
            meshcat=record is not None,
            ur3_initial_positions=[float(x) for x in motion.q_home],
            rg2_initial_opening=home_opening,
            mesh_resolution_hint=settings.mesh_resolution_hint,
            camera=still is not None,
        )
    )
    builder = DiagramBuilder()
    cell = builder.AddNamedSystem("cell", station.diagram)

    def plan(configuration, task, last):
        return motion.plan_task(configuration, task, last_token=last)

    supervisor = builder.AddNamedSystem(
        "supervisor",
        Supervisor(
            space,
            policy,
            scenario.operator(space),
            planner or plan,
            home=motion.q_home,
            home_opening=home_opening,
            period=settings.period,
            settle_time=settings.settle_time,
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
    diagram = builder.Build()
    diagram.set_name("hrc_closed_loop")

    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    plant = station.plant
    plant_context = plant.GetMyMutableContextFromRoot(root)
    station_context = station.diagram.GetMyContextFromRoot(root)
    station.deactivate_constraints(plant_context)
    supervisor_context = supervisor.GetMyContextFromRoot(root)
    status_port = supervisor.GetOutputPort("status")
    contacts = station.diagram.GetOutputPort("contact_results")
    watch = _ContactWatch(station)
    active: set = set()

    def constraint(weld: Weld):
        if weld.kind == "grasp":
            return station.grasp_constraints[weld.part]
        return station.bolt_constraints[(weld.part, weld.seat)]

    if record is not None:
        station.visualizer.StartRecording()
    start = time.perf_counter()
    simulator.Initialize()
    status: SupervisorStatus = status_port.Eval(supervisor_context)
    with ProgressLine(f"cell {scenario.name}", "sim s", interval=2.0) as bar:
        while root.get_time() < settings.max_sim_time:
            simulator.AdvanceTo(root.get_time() + settings.period)
            status = status_port.Eval(supervisor_context)
            wanted = {constraint(w) for w in status.welds}
            for cid in wanted ^ active:
                plant.SetConstraintActiveStatus(plant_context, cid, cid in wanted)
            active = wanted
            handled = status.pending[2] if status.pending else None
            watch.check(contacts.Eval(station_context), handled, root.get_time())
            if still is not None and root.get_time() >= still[0]:
                _save_still(station, station_context, Path(still[1]))
                still = None
            if progress:
                bar.update(round(root.get_time(), 1), 0, float(status.step))
            if status.mode in (Mode.DONE, Mode.FAILED):
                break
    wall = time.perf_counter() - start
    path = None
    if record is not None:
        station.visualizer.StopRecording()
        station.visualizer.PublishRecording()
        path = save_meshcat_html(station.meshcat, record)
    final_tokens = (
        station.diagram.GetOutputPort("slot_configuration").Eval(station_context).tokens()
    )
    states = status.visited
    try:
        final_kind = space.state_kind(space.index(status.state)).label
    except KeyError:
        final_kind = "unknown"
    if status.mode not in (Mode.DONE, Mode.FAILED):
        error = f"no terminal state within {settings.max_sim_time} s of simulated time"
    else:
        error = status.error
    return RunResult(
        scenario=scenario.name,
        states=states,
        names=[space.name(space.index(s)) for s in states],
        tasks=list(status.history),
        final_tokens=final_tokens,
        final_kind=final_kind,
        done=status.mode == Mode.DONE
        and space.kind[space.index(status.state)] == StateKind.TERMINAL,
        error=error,
        collisions=watch.collisions,
        sim_time=root.get_time(),
        wall_time=wall,
        recording=path,
        events=status.events,
    )


def _save_still(station: CellStation, station_context, path: Path) -> None:
    import io

    import matplotlib.image

    from hrc_drake.atomic import atomic_write_bytes

    image = station.diagram.GetOutputPort("camera.rgb_image").Eval(station_context)
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, np.array(image.data, copy=True)[:, :, :3], format="png")
    atomic_write_bytes(path, buffer.getvalue())


def simulate_command(args) -> int:
    """`hrc-drake simulate`: run a scenario headless, print the states, write the recording."""
    scenario = load_scenario(args.scenario)
    space = generate_states(load_spec(args.assembly or scenario.assembly))
    policy = load_policy(args.policy, space) if args.policy else None
    settings = RunSettings.lean() if args.lean else RunSettings.full()
    still = (args.still_time, args.still) if args.still else None
    result = run_scenario(
        scenario, policy, settings, record=args.record, progress=True, still=still
    )
    if args.json:
        json.dump(result.to_json(), sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print(f"scenario {result.scenario}: {scenario.description}")
        for t in result.tasks:
            who = "" if t.indicated == t.proposed else f" (operator: {t.indicated})"
            print(
                f"  step {t.step}: robot proposes {t.proposed}{who}; cell shows {t.observed}; "
                f"{t.end_time - t.start_time:.1f} s simulated"
            )
        print("  states:", " ".join(result.names), f"({result.final_kind})")
        print(
            f"  {result.sim_time:.1f} s simulated in {result.wall_time:.1f} s "
            f"(real-time factor {result.sim_time / max(result.wall_time, 1e-9):.2f})"
        )
        if result.collisions:
            print("  unexpected contacts:", *result.collisions[:5], sep="\n    ")
        if result.recording:
            print(f"  recording: {result.recording} (open it in a web browser)")
    if result.error:
        print(f"hrc-drake simulate: error: {result.error}", file=sys.stderr)
        return 1
    return 0 if result.done else 1


__all__ = ["RunResult", "RunSettings", "run_scenario", "shared_planner"]
