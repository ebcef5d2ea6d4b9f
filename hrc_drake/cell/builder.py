"""The cell diagram: UR3 + gripper, plate, tray and flanges in a hydroelastic MultibodyPlant.

`build_cell(scenario)` is the one place the diagram is built; everything downstream wires to the
ports it exports (see `CellStation`).
"""

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.schema import Transform
from pydrake.geometry import (
    MakeRenderEngineVtk,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    RenderEngineVtkParams,
    Role,
    RoleAssign,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JointActuatorIndex, MultibodyConstraintId, PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import MatrixGain, Saturation
from pydrake.systems.sensors import CameraConfig, RgbdSensor

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.scenario import plant_config
from hrc_drake.cell.slot_monitor import CellConfiguration, SlotMonitor
from hrc_drake.cell_models import CellDesign, add_cell_models, check_cell_models
from hrc_drake.hri.scenario import BodyConfig, Scenario
from hrc_drake.motion.poses import CellFrames, layout_poses, seat_pose
from hrc_drake.motion.scene import read_cell_frames
from hrc_drake.robot_models import RG2_MAX_OPENING, UR3_JOINTS
from hrc_drake.tasks.spec import SpecError, load_spec

TRAY = "tray"
_SAP_FAMILY = ("sap", "similar", "lagged")

# A ready posture above the plate, clear of the table and the tray.
UR3_READY = (0.0, -1.7, 1.9, -1.77, -1.5708, 0.0)
# Stiff, implicit PD (SAP integrates it implicitly, so high gains stay stable); the arm's own
# gravity is off, so these only have to reject the held part's weight and contact forces.
UR3_KP = (4000.0, 4000.0, 2000.0, 500.0, 500.0, 500.0)
UR3_KD = (200.0, 200.0, 100.0, 20.0, 20.0, 20.0)
RG2_KP, RG2_KD = 2000.0, 40.0


def _default_plant_config() -> MultibodyPlantConfig:
    # The scenario schema's physics defaults, calibrated (see `PhysicsConfig`).
    return plant_config(Scenario())


@dataclass
class CellScenario:
    """Everything `build_cell` needs (the closed loop builds one from a `Scenario` file).

    Attributes:
        design: the cell's assembly spec, layout and part instances (default: the flange case).
        plant_config: time step, contact model and discrete approximation (a SAP-family one,
            for the weld constraints) of the MultibodyPlant.
        include_robot: add the UR3 and the gripper (False: workpieces only, for fast tests).
        initial_placements: part instance -> a task token of the spec (``F1``, ``S23``,
            ``F02``) or ``tray``; unnamed parts start in the tray.
        hydroelastic_modulus: if set, replaces the modulus of every compliant geometry [Pa].
        mesh_resolution_hint: if set, replaces the hint of every compliant geometry [m].
        ur3_initial_positions: the arm's initial joint positions (UR3_JOINTS order) [rad].
        rg2_initial_opening: the gripper's initial opening between the finger insides [m].
        meshcat: start a Meshcat and add a visualizer.
        camera: add a VTK renderer and an RGB camera looking at the cell from the operator's
            side; its image is the exported output `camera.rgb_image`.
        recording_path: if set (and meshcat), `simulate_cell` saves the run there as HTML.
        simulation_duration: default duration of `simulate_cell` [s].
        operator_body: if set, the operator's kinematic body (`hrc_drake.cell.operator_body`):
            input `operator.status` (the Supervisor's status), output `operator.spheres`.
        operator_script: the body's script (default: `BoltingScript` of `operator_body`).
    """

    design: CellDesign | None = None
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
    operator_body: BodyConfig | None = None
    operator_script: object | None = None


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
    - `bolt_constraints[(part, key)]`: the part held at a seat. `key` is the task token for a
      seat on the plate (`F1`, `S12`, …) and ``<host instance>/row_<j>`` for a row of a host
      part (the token of a part there, `F0k`, depends on where the host sits).
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
    design: CellDesign
    frames: CellFrames
    meshcat: Meshcat | None = None
    visualizer: MeshcatVisualizer | None = None

    @property
    def has_robot(self) -> bool:
        """True if the UR3 and the gripper are in the cell."""
        return "ur3" in self.instances

    def part_body(self, part: str):
        """The body of the part instance `part` (e.g. ``oval_flange_1``)."""
        if part not in self.design.instance_names:
            raise KeyError(
                f"unknown part {part!r}; the parts are {', '.join(self.design.instance_names)}"
            )
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
        return layout_poses(self.frames, placements)

    def configuration(self, context: Context) -> CellConfiguration:
        """The SlotMonitor's reading in the root `context`."""
        return self.diagram.GetOutputPort("slot_configuration").Eval(context)

    def _plant_context(self, context: Context) -> Context:
        try:
            self.plant.ValidateContext(context)
            return context
        except RuntimeError:
            return self.plant.GetMyContextFromRoot(context)


def _check_scenario(scenario: CellScenario, design: CellDesign) -> None:
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
        if part not in design.instance_names:
            raise ValueError(
                f"CellScenario.initial_placements names {part!r}, which is not a part; "
                f"the parts are {', '.join(design.instance_names)}"
            )
        if where == "tray":
            continue
        try:
            placement = design.spec.placement(where)
        except SpecError as err:
            raise ValueError(f"CellScenario.initial_placements[{part}]: {err}") from err
        if placement.part != design.symbol_of(part):
            raise ValueError(
                f"CellScenario.initial_placements[{part}]: {where} places a {placement.part}, "
                f"{part} is a {design.symbol_of(part)}"
            )
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


def _fixed_pose(plant: MultibodyPlant, model, frame: str) -> RigidTransform:
    return plant.GetFrameByName(frame, model).GetFixedPoseInBodyFrame()


def _add_weld_constraints(
    plant: MultibodyPlant, instances: Mapping[str, object], design: CellDesign
) -> tuple[dict[str, MultibodyConstraintId], dict[tuple[str, str], MultibodyConstraintId]]:
    """Declare the grasp and bolt welds of every part (see `CellStation`), from the models'
    frames and the one pose rule (`motion.poses.seat_pose`)."""
    spec = design.spec
    plate = instances["base_plate"]
    plate_body = plant.GetBodyByName("base_plate", plate)
    seats = {k: _fixed_pose(plant, plate, f"slot_{k}") for k in range(1, design.slots + 1)}
    bolts: dict[tuple[str, str], MultibodyConstraintId] = {}
    grasps: dict[str, MultibodyConstraintId] = {}
    hosts = [p for p in design.parts if spec.part(p.symbol).is_host]
    for part in design.parts:
        model = instances[part.name]
        body = plant.get_body(plant.GetBodyIndices(model)[0])
        for token, mount, slots in spec.placements():
            if mount.part == part.symbol and mount.on == "base":
                bolts[(part.name, token)] = plant.AddWeldConstraint(
                    plate_body, seat_pose(seats, slots), body, RigidTransform()
                )
        mounts_on = {m.on for m in spec.mounts if m.part == part.symbol}
        for host in hosts:
            if host.symbol not in mounts_on:
                continue
            host_model = instances[host.name]
            host_body = plant.get_body(plant.GetBodyIndices(host_model)[0])
            for j in range(1, spec.part(host.symbol).footprint + 1):
                bolts[(part.name, f"{host.name}/row_{j}")] = plant.AddWeldConstraint(
                    host_body, _fixed_pose(plant, host_model, f"row_{j}"), body, RigidTransform()
                )
        if "rg2" in instances:
            tcp = plant.GetFrameByName("tcp", instances["rg2"])
            grasps[part.name] = plant.AddWeldConstraint(
                tcp.body(), tcp.GetFixedPoseInBodyFrame(), body, _fixed_pose(plant, model, "grasp")
            )
    return grasps, bolts


def build_cell(scenario: CellScenario | None = None) -> CellStation:
    """Build the cell diagram from `scenario` (default: the flange case's whole cell).

    The models come from the scenario's design (`add_cell_models`) and are checked against its
    spec before anything else (CellModelError naming the part or slot)."""
    scenario = scenario if scenario is not None else CellScenario()
    design = scenario.design if scenario.design is not None else CellDesign.of(load_spec())
    _check_scenario(scenario, design)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(scenario.plant_config, builder)
    instances = add_cell_models(plant, design, include_robot=scenario.include_robot)
    _override_hydroelastic(plant, scene_graph, scenario)
    check_cell_models(plant, scene_graph, design)
    if scenario.include_robot:
        _set_pd_gains(plant, instances)
        # The arm's PD holds it without a gravity model, as a UR controller does (gravity is
        # compensated inside the real controller); held parts still weigh on it.
        for name in ("ur3", "rg2"):
            plant.set_gravity_enabled(instances[name], False)
    grasps, bolts = _add_weld_constraints(plant, instances, design)
    plant.Finalize()
    frames = read_cell_frames(plant, scene_graph, plant.CreateDefaultContext(), design)

    layout = {p: "tray" for p in design.instance_names}
    layout.update(scenario.initial_placements)
    for part, X_WP in layout_poses(frames, layout).items():
        plant.SetDefaultFloatingBaseBodyPose(
            plant.get_body(plant.GetBodyIndices(instances[part])[0]), X_WP
        )

    monitor = builder.AddNamedSystem("slot_monitor", SlotMonitor(plant, scene_graph, frames))
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

    if scenario.operator_body is not None and scenario.include_robot:
        from hrc_drake.cell.operator_body import OperatorBody

        parts = {name: instances[name] for name in design.instance_names}
        body = builder.AddNamedSystem(
            "operator_body",
            OperatorBody(
                scene_graph, plant, parts, scenario.operator_body, scenario.operator_script
            ),
        )
        builder.Connect(
            body.GetOutputPort("geometry_pose"), scene_graph.get_source_pose_port(body.source_id)
        )
        builder.Connect(plant.get_body_poses_output_port(), body.GetInputPort("body_poses"))
        builder.ExportInput(body.GetInputPort("status"), "operator.status")
        builder.ExportOutput(body.GetOutputPort("spheres"), "operator.spheres")
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
        design=design,
        frames=frames,
        meshcat=meshcat,
        visualizer=visualizer,
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


def _add_camera(builder: DiagramBuilder, scene_graph, width: int = 1024, height: int = 640) -> None:
    """The operator's-side RGB camera, described by a Drake `CameraConfig`.

    The sensor is built from the config's cameras (`MakeCameras`) rather than with
    `ApplyCameraConfig`, which would also publish every frame on LCM: here the image renders only
    when the `camera.rgb_image` port is evaluated (a still), not at a frame rate.
    """
    config = CameraConfig(
        name="operator_view",
        width=width,
        height=height,
        focal=CameraConfig.FovDegrees(y=40.0),
        clipping_near=0.05,
        clipping_far=5.0,
        z_near=0.06,
        z_far=4.9,
        X_PB=Transform(_look_at(CAMERA_POSITION, CAMERA_TARGET)),
        renderer_name="vtk",
        renderer_class="RenderEngineVtk",
    )
    scene_graph.AddRenderer(config.renderer_name, MakeRenderEngineVtk(RenderEngineVtkParams()))
    color, depth = config.MakeCameras()
    sensor = builder.AddNamedSystem(
        config.name,
        RgbdSensor(scene_graph.world_frame_id(), config.X_PB.GetDeterministicValue(), color, depth),
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
    "save_meshcat_html",
    "simulate_cell",
]
