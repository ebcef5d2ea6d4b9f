"""The cell diagram: UR3 + gripper, plate, tray and flanges in a hydroelastic MultibodyPlant.

`build_cell(scenario)` is the one place the diagram is built; everything downstream wires to the
ports it exports (see `CellStation`).
"""

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
    RoleAssign,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import LoadModelDirectives, ProcessModelDirectives
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JointActuatorIndex, MultibodyConstraintId, PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, Saturation
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.slot_monitor import (
    DEFAULT_HOST_TAGS,
    DEFAULT_PART_SYMBOLS,
    CellConfiguration,
    SlotMonitor,
)
from hrc_drake.resources import package_uri
from hrc_drake.robot_models import RG2_MAX_OPENING, UR3_JOINTS, make_parser
from hrc_drake.tasks.tokens import parse_base_token, placement_token

CELL_DIRECTIVES = "cell.dmd.yaml"
WORKCELL_DIRECTIVES = "cell/workcell.dmd.yaml"
PARTS = ("oval_flange_1", "oval_flange_2", "square_flange")
TRAY = "tray"
_SAP_FAMILY = ("sap", "similar", "lagged")

# A ready posture above the plate, clear of the table and the tray.
UR3_READY = (0.0, -1.7, 1.9, -1.77, -1.5708, 0.0)
# Stiff, implicit PD (SAP integrates it implicitly, so high gains stay stable); gravity is fed
# forward, so these only have to reject the held part's weight and contact forces.
UR3_KP = (4000.0, 4000.0, 2000.0, 500.0, 500.0, 500.0)
UR3_KD = (200.0, 200.0, 100.0, 20.0, 20.0, 20.0)
RG2_KP, RG2_KD = 2000.0, 40.0


def _default_plant_config() -> MultibodyPlantConfig:
    # 5 ms: flanges settle in < 0.5 s at a real-time factor ~1 (drake-calibration.md); 10 ms
    # leaves them moving. `sap`: at 5 ms the light oval flange (67 g) keeps chattering in its
    # pocket under `lagged`/`similar` (0.4 N of its 0.66 N weight carried, 9 mm/s left after
    # 2 s) and rests exactly under `sap`, at the same cost.
    return MultibodyPlantConfig(
        time_step=5e-3,
        contact_model="hydroelastic_with_fallback",
        discrete_contact_approximation="sap",
        contact_surface_representation="polygon",
    )


@dataclass
class CellScenario:
    """Everything `build_cell` needs; load one from YAML with `load_scenario`.

    Attributes:
        plant_config: time step, contact model and discrete approximation (a SAP-family one,
            for the weld constraints) of the MultibodyPlant.
        include_robot: add the UR3 and the gripper (False: workpieces only, for fast tests).
        initial_placements: part instance -> a task token (``F1``, ``S23``, ``F02``) or
            ``tray``; unnamed parts start in the tray.
        hydroelastic_modulus: if set, replaces the modulus of every compliant geometry [Pa].
        mesh_resolution_hint: if set, replaces the hint of every compliant geometry [m].
        ur3_initial_positions: the arm's initial joint positions (UR3_JOINTS order) [rad].
        rg2_initial_opening: the gripper's initial opening between the finger insides [m].
        meshcat: start a Meshcat and add a visualizer.
        camera: add a VTK renderer and an RGB camera looking at the cell from the operator's
            side; its image is the exported output `camera.rgb_image`.
        recording_path: if set (and meshcat), `simulate_cell` saves the run there as HTML.
        simulation_duration: default duration of `simulate_cell` [s].
    """

    plant_config: MultibodyPlantConfig = field(default_factory=_default_plant_config)
    include_robot: bool = True
    initial_placements: dict[str, str] = field(default_factory=dict)
    hydroelastic_modulus: float | None = None
    mesh_resolution_hint: float | None = None
    ur3_initial_positions: list[float] = field(default_factory=lambda: list(UR3_READY))
    rg2_initial_opening: float = 0.08
    meshcat: bool = False
    camera: bool = False
    recording_path: str | None = None
    simulation_duration: float = 0.5


def load_scenario(text: str | None = None, path: str | Path | None = None) -> CellScenario:
    """A CellScenario from YAML `text` or a file: unknown keys are errors, missing ones default."""
    if (text is None) == (path is None):
        raise ValueError("load_scenario: pass exactly one of text= or path=")
    if path is not None:
        return yaml_load_typed(schema=CellScenario, filename=str(path))
    return yaml_load_typed(schema=CellScenario, data=text)


@dataclass(frozen=True)
class CellStation:
    """The built cell.

    Exported ports of `diagram`: inputs `ur3.desired_state` (12: q, v in UR3_JOINTS order) and
    `rg2.desired_opening` (1: metres between the finger insides, 0..0.110), robot only; outputs
    `plant_state`, `contact_results`, `body_poses`, `query_object`, `slot_configuration`
    (CellConfiguration), and with the robot `ur3.state`, `rg2.state`.

    Weld constraints (declared before Finalize, toggled with
    `plant.SetConstraintActiveStatus(plant_context, id, bool)`):
    - `grasp_constraints[part]`: `rg2_base` <-> part with the gripper's `tcp` at the part's
      `grasp` frame (robot only);
    - `bolt_constraints[(part, key)]`: the part held at a seat. `key` is the task token for the
      plate (`F1`, `F2`, `F3`, `S12`, `S23`) and the row frame (`row_1`, `row_2`) for an oval
      flange on the square: its token, `F0k`, depends on where the square sits (row_1 is over the
      lower base slot the square covers when the square is placed as its convention says).
    Drake makes a new context with every constraint active: use `create_default_context()`
    (or `deactivate_constraints`) so that they start inactive.
    """

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    scenario: CellScenario
    instances: Mapping[str, object]
    monitor: SlotMonitor
    grasp_constraints: Mapping[str, MultibodyConstraintId]
    bolt_constraints: Mapping[tuple[str, str], MultibodyConstraintId]
    meshcat: Meshcat | None = None
    visualizer: MeshcatVisualizer | None = None
    part_symbols: Mapping[str, str] = field(default_factory=lambda: dict(DEFAULT_PART_SYMBOLS))

    @property
    def has_robot(self) -> bool:
        """True if the UR3 and the gripper are in the cell."""
        return "ur3" in self.instances

    def part_body(self, part: str):
        """The body of the part instance `part` (e.g. ``oval_flange_1``)."""
        if part not in PARTS:
            raise KeyError(f"unknown part {part!r}; the parts are {', '.join(PARTS)}")
        return self.plant.get_body(self.plant.GetBodyIndices(self.instances[part])[0])

    def deactivate_constraints(self, context: Context) -> None:
        """Turn every grasp and bolt weld off in `context` (root or plant context)."""
        plant_context = self._plant_context(context)
        for cid in [*self.grasp_constraints.values(), *self.bolt_constraints.values()]:
            self.plant.SetConstraintActiveStatus(plant_context, cid, False)

    def create_default_context(self) -> Context:
        """A root context with every weld constraint inactive and the robot inputs holding the
        initial posture and opening (so it can be simulated as is)."""
        context = self.diagram.CreateDefaultContext()
        self.deactivate_constraints(context)
        if self.has_robot:
            self.hold_robot(context)
        return context

    def hold_robot(self, context: Context, opening: float | None = None) -> None:
        """Fix the robot inputs of `context` to hold the arm where it is, fingers at `opening`
        (default: as they are)."""
        plant_context = self._plant_context(context)
        q = self.plant.GetPositions(plant_context, self.instances["ur3"])
        self.diagram.GetInputPort("ur3.desired_state").FixValue(
            context, np.concatenate([q, np.zeros_like(q)])
        )
        if opening is None:
            opening = float(np.sum(self.plant.GetPositions(plant_context, self.instances["rg2"])))
        self.diagram.GetInputPort("rg2.desired_opening").FixValue(context, [opening])

    def placement_poses(self, placements: Mapping[str, str]) -> dict[str, RigidTransform]:
        """World poses of parts seated as `placements` says (part instance -> token or "tray")."""
        return placement_poses(self.plant, placements, self.part_symbols)

    def configuration(self, context: Context) -> CellConfiguration:
        """The SlotMonitor's reading in the root `context`."""
        return self.diagram.GetOutputPort("slot_configuration").Eval(context)

    def _plant_context(self, context: Context) -> Context:
        try:
            self.plant.ValidateContext(context)
            return context
        except RuntimeError:
            return self.plant.GetMyContextFromRoot(context)


class _GravityFeedForward(LeafSystem):
    """Actuation that cancels gravity on the UR3 joints (fed forward to the PD actuators)."""

    def __init__(self, plant: MultibodyPlant, ur3):
        super().__init__()
        self._plant = plant
        self._context = plant.CreateDefaultContext()
        self._rows = [
            plant.get_joint_actuator(a).joint().velocity_start()
            for a in plant.GetJointActuatorIndices(ur3)
        ]
        self.DeclareVectorInputPort("plant_state", plant.num_multibody_states())
        self.DeclareVectorOutputPort("actuation", len(self._rows), self._calc)

    def _calc(self, context, output) -> None:
        self._plant.SetPositionsAndVelocities(self._context, self.get_input_port().Eval(context))
        tau_g = self._plant.CalcGravityGeneralizedForces(self._context)
        output.SetFromVector(-tau_g[self._rows])


def _check_scenario(scenario: CellScenario) -> None:
    approximation = scenario.plant_config.discrete_contact_approximation
    if approximation not in _SAP_FAMILY:
        raise ValueError(
            f"CellScenario.plant_config.discrete_contact_approximation={approximation!r}: the "
            f"cell's weld constraints need a SAP-family one; use one of {', '.join(_SAP_FAMILY)}"
        )
    if not scenario.plant_config.time_step > 0:
        raise ValueError(
            "CellScenario.plant_config.time_step must be > 0: the cell is a discrete plant "
            "(5e-3 is the calibrated choice)"
        )
    for part, where in scenario.initial_placements.items():
        if part not in PARTS:
            raise ValueError(
                f"CellScenario.initial_placements names {part!r}, which is not a part; "
                f"the parts are {', '.join(PARTS)}"
            )
        if where != "tray":
            parse_base_token(where)
    if len(scenario.ur3_initial_positions) != 6:
        raise ValueError("CellScenario.ur3_initial_positions needs 6 joint positions")
    if not 0.0 <= scenario.rg2_initial_opening <= RG2_MAX_OPENING:
        raise ValueError(f"CellScenario.rg2_initial_opening must be in [0, {RG2_MAX_OPENING}] m")


def _override_hydroelastic(plant, scene_graph, scenario: CellScenario) -> None:
    if scenario.hydroelastic_modulus is None and scenario.mesh_resolution_hint is None:
        return
    inspector = scene_graph.model_inspector()
    source = plant.get_source_id()
    for gid in inspector.GetAllGeometryIds(Role.kProximity):
        props = inspector.GetProximityProperties(gid)
        if props is None or not props.HasProperty("hydroelastic", "hydroelastic_modulus"):
            continue
        props = props.__class__(props)
        if scenario.hydroelastic_modulus is not None:
            props.UpdateProperty(
                "hydroelastic", "hydroelastic_modulus", scenario.hydroelastic_modulus
            )
        if scenario.mesh_resolution_hint is not None and props.HasProperty(
            "hydroelastic", "resolution_hint"
        ):
            props.UpdateProperty("hydroelastic", "resolution_hint", scenario.mesh_resolution_hint)
        scene_graph.AssignRole(source, gid, props, RoleAssign.kReplace)


def _seat_frames(plant: MultibodyPlant, model, prefix: str) -> dict[int, object]:
    frames = {}
    k = 1
    while plant.HasFrameNamed(f"{prefix}{k}", model):
        frames[k] = plant.GetFrameByName(f"{prefix}{k}", model)
        k += 1
    return frames


def _midpoint(X_a: RigidTransform, X_b: RigidTransform) -> RigidTransform:
    return RigidTransform(X_a.rotation(), (X_a.translation() + X_b.translation()) / 2)


def _span(plant: MultibodyPlant, inspector, body) -> int:
    """How many base slots a part covers: one boss per covered slot."""
    names = [inspector.GetName(g) for g in plant.GetCollisionGeometriesForBody(body)]
    return max(1, sum(1 for n in names if n.split("::")[-1].startswith("boss")))


def _add_weld_constraints(plant: MultibodyPlant, inspector, instances, symbols):
    plate = instances["base_plate"]
    plate_body = plant.GetBodyByName("base_plate", plate)
    slots = _seat_frames(plant, plate, "slot_")
    bolts: dict[tuple[str, str], MultibodyConstraintId] = {}
    grasps: dict[str, MultibodyConstraintId] = {}
    for part in PARTS:
        model = instances[part]
        body = plant.get_body(plant.GetBodyIndices(model)[0])
        span = _span(plant, inspector, body)
        for start in range(1, len(slots) - span + 2):
            run = tuple(range(start, start + span))
            X_plate_seat = slots[run[0]].GetFixedPoseInBodyFrame()
            if span == 2:
                X_plate_seat = _midpoint(X_plate_seat, slots[run[1]].GetFixedPoseInBodyFrame())
            token = placement_token(symbols[part], run)
            bolts[(part, token)] = plant.AddWeldConstraint(
                plate_body, X_plate_seat, body, RigidTransform()
            )
        if span == 1:
            for host, _tag in DEFAULT_HOST_TAGS.items():
                host_model = instances[host]
                host_body = plant.get_body(plant.GetBodyIndices(host_model)[0])
                for j, row in _seat_frames(plant, host_model, "row_").items():
                    bolts[(part, f"row_{j}")] = plant.AddWeldConstraint(
                        host_body, row.GetFixedPoseInBodyFrame(), body, RigidTransform()
                    )
        if "rg2" in instances:
            tcp = plant.GetFrameByName("tcp", instances["rg2"])
            grasp = plant.GetFrameByName("grasp", model)
            grasps[part] = plant.AddWeldConstraint(
                tcp.body(),
                tcp.GetFixedPoseInBodyFrame(),
                body,
                grasp.GetFixedPoseInBodyFrame(),
            )
    return grasps, bolts


def placement_poses(
    plant: MultibodyPlant,
    placements: Mapping[str, str],
    part_symbols: Mapping[str, str] = DEFAULT_PART_SYMBOLS,
) -> dict[str, RigidTransform]:
    """World poses of the parts seated as `placements` says (part -> token or ``tray``).

    Derived from the frames (docs/conventions.md): on slot k, `X_W_slot_k`; the square on slots
    j, j+1, the midpoint of theirs; an oval flange on the square (``F0k``), `X_W_square` times
    the square's row frame over base slot k (the square must be in `placements` too).
    """
    context = plant.CreateDefaultContext()
    plate = plant.GetModelInstanceByName("base_plate")
    slots = {k: f.CalcPoseInWorld(context) for k, f in _seat_frames(plant, plate, "slot_").items()}
    tray = plant.GetModelInstanceByName(TRAY)
    poses: dict[str, RigidTransform] = {}
    hosted = []
    for part, where in placements.items():
        if part not in part_symbols:
            raise ValueError(f"unknown part {part!r}; the parts are {', '.join(part_symbols)}")
        if where == "tray":
            poses[part] = plant.GetFrameByName(f"home_{part}", tray).CalcPoseInWorld(context)
            continue
        symbol = part_symbols[part]
        tags = set(DEFAULT_HOST_TAGS.values())
        if where.startswith(symbol) and where[len(symbol) : len(symbol) + 1] in tags:
            hosted.append((part, where))
            continue
        token_symbol, slots_named = parse_base_token(where)
        if token_symbol != symbol:
            raise ValueError(f"token {where!r} does not place part {part!r} (symbol {symbol!r})")
        missing = [k for k in slots_named if k not in slots]
        if missing:
            raise ValueError(f"{where!r}: the plate has no slot {missing[0]}")
        X = slots[slots_named[0]]
        if len(slots_named) == 2:
            X = _midpoint(X, slots[slots_named[1]])
        poses[part] = X
    for part, where in hosted:
        tag, k = where[len(part_symbols[part])], int(where[len(part_symbols[part]) + 1 :])
        hosts = [h for h, t in DEFAULT_HOST_TAGS.items() if t == tag]
        if not hosts or hosts[0] not in poses:
            raise ValueError(f"{where!r} for {part!r} needs its host part placed in the same call")
        host = plant.GetModelInstanceByName(hosts[0])
        X_W_host = poses[hosts[0]]
        for row in _seat_frames(plant, host, "row_").values():
            X = X_W_host @ row.GetFixedPoseInBodyFrame()
            if np.linalg.norm((X.translation() - slots[k].translation())[:2]) < 1e-3:
                poses[part] = X
                break
        else:
            raise ValueError(f"{where!r}: no row of {hosts[0]} is over base slot {k}")
    return poses


def build_cell(scenario: CellScenario | None = None) -> CellStation:
    """Build the cell diagram from `scenario` (default: the whole cell, no Meshcat)."""
    scenario = scenario if scenario is not None else CellScenario()
    _check_scenario(scenario)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)
    parser = make_parser(plant)
    directives_uri = package_uri(CELL_DIRECTIVES if scenario.include_robot else WORKCELL_DIRECTIVES)
    directives = LoadModelDirectives(parser.package_map().ResolveUrl(directives_uri))
    ProcessModelDirectives(directives, plant, parser)
    _override_hydroelastic(plant, scene_graph, scenario)

    names = ["table", "base_plate", TRAY, *PARTS]
    if scenario.include_robot:
        names += ["ur3", "rg2"]
    instances = {n: plant.GetModelInstanceByName(n) for n in names}
    symbols = dict(DEFAULT_PART_SYMBOLS)
    if scenario.include_robot:
        _set_pd_gains(plant, instances)
    grasps, bolts = _add_weld_constraints(plant, scene_graph.model_inspector(), instances, symbols)
    plant.Finalize()

    poses = placement_poses(plant, {p: "tray" for p in PARTS}, symbols)
    poses.update(placement_poses(plant, scenario.initial_placements, symbols))
    for part, X_WP in poses.items():
        plant.SetDefaultFloatingBaseBodyPose(
            plant.get_body(plant.GetBodyIndices(instances[part])[0]), X_WP
        )

    monitor = builder.AddNamedSystem("slot_monitor", SlotMonitor(plant, scene_graph, symbols))
    builder.Connect(
        plant.get_contact_results_output_port(), monitor.GetInputPort("contact_results")
    )
    builder.Connect(plant.get_body_poses_output_port(), monitor.GetInputPort("body_poses"))
    builder.ExportOutput(monitor.GetOutputPort("slot_configuration"), "slot_configuration")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    builder.ExportOutput(plant.get_contact_results_output_port(), "contact_results")
    builder.ExportOutput(plant.get_body_poses_output_port(), "body_poses")
    builder.ExportOutput(scene_graph.get_query_output_port(), "query_object")

    if scenario.include_robot:
        ur3, rg2 = instances["ur3"], instances["rg2"]
        plant.SetDefaultPositions(ur3, scenario.ur3_initial_positions)
        plant.SetDefaultPositions(rg2, [scenario.rg2_initial_opening / 2] * 2)
        builder.ExportInput(plant.get_desired_state_input_port(ur3), "ur3.desired_state")
        gravity = builder.AddNamedSystem("ur3_gravity", _GravityFeedForward(plant, ur3))
        builder.Connect(plant.get_state_output_port(), gravity.get_input_port())
        builder.Connect(gravity.get_output_port(), plant.get_actuation_input_port(ur3))
        clip = builder.AddNamedSystem("rg2_clip", Saturation([0.0], [RG2_MAX_OPENING]))
        # Each finger joint runs half the opening; velocities are commanded zero.
        split = builder.AddNamedSystem(
            "rg2_command", MatrixGain(np.array([[0.5], [0.5], [0], [0]]))
        )
        builder.Connect(clip.get_output_port(), split.get_input_port())
        builder.Connect(split.get_output_port(), plant.get_desired_state_input_port(rg2))
        builder.ExportInput(clip.get_input_port(), "rg2.desired_opening")
        builder.ExportOutput(plant.get_state_output_port(ur3), "ur3.state")
        builder.ExportOutput(plant.get_state_output_port(rg2), "rg2.state")

    if scenario.camera:
        _add_camera(builder, scene_graph)
    meshcat = visualizer = None
    if scenario.meshcat:
        meshcat = Meshcat()
        visualizer = MeshcatVisualizer.AddToBuilder(
            builder,
            scene_graph,
            meshcat,
            MeshcatVisualizerParams(delete_on_initialization_event=False),
        )
    diagram = builder.Build()
    diagram.set_name("hrc_cell")
    return CellStation(
        diagram=diagram,
        plant=plant,
        scene_graph=scene_graph,
        scenario=scenario,
        instances=instances,
        monitor=monitor,
        grasp_constraints=grasps,
        bolt_constraints=bolts,
        meshcat=meshcat,
        visualizer=visualizer,
        part_symbols=symbols,
    )


CAMERA_POSITION = (0.95, -0.75, 0.80)
CAMERA_TARGET = (0.17, -0.06, 0.14)


def _look_at(position, target) -> RigidTransform:
    # Camera frame of RgbdSensor: +z forward, +x right, +y down in the image.
    p, t = np.asarray(position), np.asarray(target)
    z = (t - p) / np.linalg.norm(t - p)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RigidTransform(RotationMatrix(np.column_stack([x, y, z])), p)


def _add_camera(builder: DiagramBuilder, scene_graph, width: int = 1024, height: int = 640):
    scene_graph.AddRenderer("vtk", MakeRenderEngineVtk(RenderEngineVtkParams()))
    core = RenderCameraCore(
        "vtk",
        CameraInfo(width=width, height=height, fov_y=np.radians(40)),
        ClippingRange(0.05, 5.0),
        RigidTransform(),
    )
    sensor = builder.AddNamedSystem(
        "camera",
        RgbdSensor(
            scene_graph.world_frame_id(),
            _look_at(CAMERA_POSITION, CAMERA_TARGET),
            ColorRenderCamera(core),
            DepthRenderCamera(core, DepthRange(0.06, 4.9)),
        ),
    )
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    builder.ExportOutput(sensor.color_image_output_port(), "camera.rgb_image")


def _actuators(plant: MultibodyPlant, model) -> list:
    # GetJointActuatorIndices(model) is empty before Finalize.
    actuators = [
        plant.get_joint_actuator(JointActuatorIndex(i)) for i in range(plant.num_actuators())
    ]
    return [a for a in actuators if a.model_instance() == model]


def _set_pd_gains(plant: MultibodyPlant, instances) -> None:
    ur3_joints = [a.joint().name() for a in _actuators(plant, instances["ur3"])]
    if tuple(ur3_joints) != UR3_JOINTS:
        raise ValueError(
            f"ur3 actuators are ordered {ur3_joints}, expected {list(UR3_JOINTS)}: the "
            "`ur3.desired_state` port is documented in UR3_JOINTS order; fix the URDF transmissions"
        )
    for a, kp, kd in zip(_actuators(plant, instances["ur3"]), UR3_KP, UR3_KD, strict=True):
        a.set_controller_gains(PdControllerGains(p=kp, d=kd))
    for a in _actuators(plant, instances["rg2"]):
        a.set_controller_gains(PdControllerGains(p=RG2_KP, d=RG2_KD))


def simulate_cell(
    station: CellStation,
    context: Context | None = None,
    duration: float | None = None,
    recording_path: str | Path | None = None,
) -> Simulator:
    """Simulate the cell for `duration` (default: the scenario's) from `context` (default: a
    fresh `create_default_context()`); with Meshcat, record and save the run as HTML at
    `recording_path` (default: the scenario's). Returns the simulator."""
    context = context if context is not None else station.create_default_context()
    duration = duration if duration is not None else station.scenario.simulation_duration
    path = recording_path if recording_path is not None else station.scenario.recording_path
    if path is not None and station.meshcat is None:
        raise ValueError("a recording needs Meshcat: set `meshcat: true` in the CellScenario")
    simulator = Simulator(station.diagram, context)
    if path is not None:
        station.visualizer.StartRecording()
    simulator.AdvanceTo(context.get_time() + duration)
    if path is not None:
        station.visualizer.StopRecording()
        station.visualizer.PublishRecording()
        save_meshcat_html(station.meshcat, path)
    return simulator


def save_meshcat_html(meshcat: Meshcat, path: str | Path) -> Path:
    """Write `meshcat.StaticHtml()` (a self-contained page) to `path`, atomically."""
    return atomic_write_text(path, meshcat.StaticHtml())


__all__ = [
    "CellScenario",
    "CellStation",
    "build_cell",
    "load_scenario",
    "placement_poses",
    "save_meshcat_html",
    "simulate_cell",
]
