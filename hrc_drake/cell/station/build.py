"""The simulated cell station: one diagram from one scenario, behind the ports a real cell has.

`make_cell_station(scenario, meshcat)` builds, as Drake's `examples/hardware_sim` and the
`manipulation` course's `MakeHardwareStation` do, everything from the typed `Scenario`: the
MultibodyPlant (time step, contact approximation, contact materials), the UR3 and the RG2-like
gripper with their servos (gains and starting posture from `station:`), the plate, tray and
parts generated from the assembly spec and its layout, the configuration sensor, the simulated
operator with its body, and a camera. Its ports (`docs/station.md`):

- inputs, what a controller commands: `ur3.position`, `ur3.velocity`, `rg2.opening`,
  `rg2.force`, `hri.prompt`;
- outputs, what a real cell measures: `ur3.state_estimated`, `ur3.tcp_force`,
  `rg2.state_measured`, `rg2.grip_detected`, `configuration`, `operator.body`, `hri.indication`;
- outputs for the simulation only (runner, recordings, tests): `sim.welds`, `sim.plant_state`,
  `sim.contact_results`, `sim.body_poses`, `sim.query_object`, `sim.camera.rgb_image`,
  `sim.held_part` (the part the contact sensor reads as held; "": none).

The gripper holds a part by its pads' contact and friction, squeezing with the commanded force
(`hrc_drake.cell.station.gripper`): a part can slip, fall or fail to seat. What only a simulator can
do stays inside: the simulated operator answers the prompts and bolts, its body moves by its
activity, and its bolts fix each part where it sits when bolted (`hrc_drake.cell.station.welds`),
switched through the station's `Simulator` monitor (`CellStation.welds_changed`,
`CellStation.apply_welds`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    MakeRenderEngineVtk,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    ProximityProperties,
    RenderEngineVtkParams,
    RoleAssign,
)
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    ContactResults,
    CoulombFriction,
    MultibodyPlant,
)
from pydrake.multibody.tree import BodyIndex, PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, Demultiplexer
from pydrake.systems.sensors import CameraConfig, RgbdSensor

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.person import desk_of
from hrc_drake.cell.ports import NOBODY
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.scenario import (
    OPERATOR_VIEW,
    cell_configs,
    cell_design,
    contact_material,
    make_simulator,
    motion_options,
    plant_config,
    scene_graph_config,
)
from hrc_drake.cell.ssm import function_settings
from hrc_drake.cell.station.arm_servo import GravityCompensation, servo_actuators
from hrc_drake.cell.station.camera import export_configuration
from hrc_drake.cell.station.camera_verdicts import check_camera_noise
from hrc_drake.cell.station.cell_station import CellStation
from hrc_drake.cell.station.contacts import geometry_owners, owner_pairs
from hrc_drake.cell.station.desk import add_bins, desk_script
from hrc_drake.cell.station.faults import FaultInjector, SilentOperator
from hrc_drake.cell.station.gripper import add_gripper_ports, set_finger_gains
from hrc_drake.cell.station.obstacle import (
    SeatPositions,
    filter_obstacle_contacts,
    mount_obstacle,
    mounted_obstacles,
)
from hrc_drake.cell.station.operator_body import BodyScript, KnowsWhenFree, OperatorBody
from hrc_drake.cell.station.safety_function import SafetyFunction
from hrc_drake.cell.station.safety_sensor import add_safety_sensor
from hrc_drake.cell.station.sensors import export_measured
from hrc_drake.cell.station.sim_operator import SimulatedOperator
from hrc_drake.cell.station.slot_monitor import SlotMonitor
from hrc_drake.cell.station.welds import Bolts
from hrc_drake.cell.station.wrist import add_tcp_force
from hrc_drake.cell_models import CellDesign, add_cell_models
from hrc_drake.motion.poses import IN_TRAY, CellFrames, layout_poses
from hrc_drake.motion.scene import read_cell_frames
from hrc_drake.obstacle_models import DEBRIS, OBSTACLE
from hrc_drake.robot_models import set_rg2_opening
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS
from hrc_drake.scenario.schema import Activity, Scenario
from hrc_drake.scenario.sensors import camera_model
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.tasks.decide import Operator
from hrc_drake.tasks.graph import StateSpace, generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.workpiece_sdf import BOSS_MODULUS_SCALE, is_boss


def check_station_scenario(scenario: Scenario, design: CellDesign) -> None:
    """Value checks of what the station builds; ValueError naming the scenario key."""
    # The plant's contact approximation (SAP-family, for the bolts) is checked where the
    # scenario's plant_config is read, `hrc_drake.cell.scenario.cell_configs`.
    station = scenario.station
    for part, where in station.initial_placements.items():
        key = f"station.initial_placements.{part}"
        if part not in design.instance_names:
            raise ValueError(f"{key}: not a part; the parts are {', '.join(design.instance_names)}")
        if where == IN_TRAY:
            continue
        try:
            placement = design.spec.placement(where)
        except SpecError as err:
            raise ValueError(f"{key}: {err}") from err
        if placement.part != design.symbol_of(part):
            raise ValueError(
                f"{key}: {where} places a {placement.part}, {part} is a {design.symbol_of(part)}"
            )
    for key, values in (("initial_positions", station.ur3.initial_positions),):
        if values and len(values) != len(UR3_JOINTS):
            raise ValueError(f"station.ur3.{key}: give {len(UR3_JOINTS)} joint positions [rad]")
    camera = camera_model(scenario.sensors)
    if camera is not None:
        check_camera_noise(camera.noise, camera.angle_noise)


def _set_servo_gains(plant: MultibodyPlant, instances, scenario: Scenario) -> None:
    arm, gripper = scenario.station.ur3, scenario.station.rg2
    joints = tuple(a.joint().name() for a in servo_actuators(plant, instances[UR3]))
    if joints != UR3_JOINTS:
        raise ValueError(
            f"ur3 actuators are ordered {list(joints)}, expected {list(UR3_JOINTS)}: the "
            "`ur3.position` port is documented in UR3_JOINTS order; fix the URDF transmissions"
        )
    arm_actuators = servo_actuators(plant, instances[UR3])
    for actuator, kp, kd in zip(arm_actuators, arm.kp, arm.kd, strict=True):
        actuator.set_controller_gains(PdControllerGains(p=kp, d=kd))
    set_finger_gains(plant, instances[GRIPPER], gripper.kp, gripper.kd)
    # The arm's servo compensates its links' weight (`hrc_drake.cell.station.arm_servo`), as a UR
    # controller does; the gripper's fingers are servoed without a weight model. Held parts
    # still weigh on both.
    plant.set_gravity_enabled(instances[GRIPPER], False)


def _apply_material(plant: MultibodyPlant, scene_graph, scenario: Scenario) -> None:
    """Give every collision geometry the scenario's friction but the gripper's fingers, whose
    rubber pads state their own (models/rg2/rg2.sdf). Drake's parsers write a friction of 1.0
    on every geometry whose model states none, so SceneGraph's defaults would never apply.
    A part's boss, whose box reaches up into the part, takes the scenario's modulus scaled by
    `BOSS_MODULUS_SCALE` (hrc_drake.workpiece_sdf)."""
    contact = contact_material(scenario)
    friction = CoulombFriction(contact.static_friction, contact.dynamic_friction)
    boss_modulus = contact.hydroelastic_modulus * BOSS_MODULUS_SCALE
    inspector = scene_graph.model_inspector()
    for index in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(index))
        if plant.GetModelInstanceName(body.model_instance()) == GRIPPER and body.name().endswith(
            "finger"
        ):
            continue
        for gid in plant.GetCollisionGeometriesForBody(body):
            props = ProximityProperties(inspector.GetProximityProperties(gid))
            props.UpdateProperty("material", "coulomb_friction", friction)
            if is_boss(inspector.GetName(gid)):
                props.UpdateProperty("hydroelastic", "hydroelastic_modulus", boss_modulus)
            scene_graph.AssignRole(plant.get_source_id(), gid, props, RoleAssign.kReplace)


def _add_plant(
    builder: DiagramBuilder,
    scenario: Scenario,
    design: CellDesign,
    arm_start: Sequence[float] | None = None,
):
    """The plant with the cell's models and servos; (plant, scene graph, instances, bolts,
    frames), parts at their initial placements and the arm at `arm_start` (default: the
    scenario's initial positions, else the ready posture)."""
    plant, scene_graph = AddMultibodyPlant(
        plant_config(scenario), scene_graph_config(scenario), builder
    )
    robot = scenario.station.robot
    instances = add_cell_models(plant, design, include_robot=robot)
    _apply_material(plant, scene_graph, scenario)
    if robot:
        _set_servo_gains(plant, instances, scenario)
    obstacles = mounted_obstacles(scenario.faults) if robot else ()
    for name in obstacles:
        instances[name] = mount_obstacle(plant, name)
    plant.Finalize()
    for name in obstacles:
        filter_obstacle_contacts(plant, scene_graph, name)
    bolts = Bolts.of(plant, instances, design)
    frames = read_cell_frames(plant, scene_graph, plant.CreateDefaultContext(), design)
    layout = {p: IN_TRAY for p in design.instance_names}
    layout.update(scenario.station.initial_placements)
    for part, X_WP in layout_poses(frames, layout).items():
        plant.SetDefaultFloatingBaseBodyPose(
            plant.get_body(plant.GetBodyIndices(instances[part])[0]), X_WP
        )
    if robot:
        arm = scenario.station.ur3
        if arm_start is None:
            arm_start = arm.initial_positions or arm.ready
        plant.SetDefaultPositions(instances[UR3], [float(x) for x in arm_start])
        set_rg2_opening(plant, None, scenario.station.rg2.initial_opening, instances[GRIPPER])
    return plant, scene_graph, instances, bolts, frames


def _add_arm(
    builder: DiagramBuilder, plant: MultibodyPlant, ur3, scenario: Scenario, frames: CellFrames
) -> SafetyFunction:
    """`ur3.position` and `ur3.velocity` into the arm's servo through the safety function
    (returned; its measurements are connected once the station has them,
    `_connect_safety_function`); `ur3.state_estimated`, `ur3.tcp_force` (the wrist load,
    `hrc_drake.cell.station.wrist`), `safety.stop` and `safety.mode` out, `safety.unlock`,
    `ur3.command_stale` and `sim.safety.reduced` in."""
    function = builder.AddNamedSystem(
        "safety_function",
        SafetyFunction(
            RobotEnvelope(frames.design),
            function_settings(scenario.safety),
            motion_options(scenario).joint_acceleration_limit,
            scenario.run.period,
            frames.widths,
        ),
    )
    builder.Connect(
        function.GetOutputPort("desired_state"), plant.get_desired_state_input_port(ur3)
    )
    builder.Connect(plant.get_state_output_port(ur3), function.GetInputPort("ur3.state"))
    for name in ("ur3.position", "ur3.velocity", "safety.unlock"):
        builder.ExportInput(function.GetInputPort(name), name)
    # The UR's configurable reduced-mode input, wired by the cell's integrator, not the
    # controller (a test sets it); unconnected, off.
    builder.ExportInput(function.GetInputPort("safety.reduced"), "sim.safety.reduced")
    # The real-time link's watchdog (`hrc_drake.cell.link.realtime_server`); unconnected, never.
    builder.ExportInput(function.GetInputPort("command_stale"), "ur3.command_stale")
    # What the servo follows (the command, or the function's brake or blend): RTDE's target_q
    # and target_qd, which the real-time link sends beside the measurement; its positions are
    # `ur3.target`, which the controller's tracking check compares the arm with (in a stop
    # the servo follows the brake, not the plan).
    builder.ExportOutput(function.GetOutputPort("desired_state"), "sim.ur3.target")
    joints = len(UR3_JOINTS)
    target = builder.AddNamedSystem("ur3_target", Demultiplexer([joints, joints]))
    builder.Connect(function.GetOutputPort("desired_state"), target.get_input_port())
    builder.ExportOutput(target.get_output_port(0), "ur3.target")
    for name in ("safety.stop", "safety.mode"):
        builder.ExportOutput(function.GetOutputPort(name), name)
    export_measured(builder, plant.get_state_output_port(ur3), "ur3.state_estimated", scenario)
    gripper = plant.GetModelInstanceByName(GRIPPER)
    export_measured(builder, add_tcp_force(builder, plant, gripper), "ur3.tcp_force", scenario)
    weight = builder.AddNamedSystem("ur3_gravity", GravityCompensation(plant, ur3))
    builder.Connect(plant.get_state_output_port(ur3), weight.get_input_port())
    builder.Connect(weight.get_output_port(), plant.get_actuation_input_port(ur3))
    return function


def body_script_of(scenario: Scenario, frames: CellFrames, body_script=None):
    """The operator body's script: the one given, else the scenario's activity (`desk`: this
    operator seed's person on the layout's desk, a `DeskScript`, modelled or unseen as
    `body.behaviour` says; `bolting`: `BoltingScript`, as None)."""
    if body_script is not None or scenario.body.activity != Activity.DESK:
        return body_script
    desk = desk_of(frames, frames.design.layout)
    return desk_script(scenario.body, scenario.operator.seed, desk)


def _add_operator(
    builder, plant, scene_graph, parts, scenario: Scenario, operator, body_script, injector=None
):
    """The simulated operator and its body (a tracker that sees nobody without one); returns
    the simulated operator. With a `tracker-loss` fault the body reaches the tracker's port
    through the fault `injector`, and its exact spheres are `sim.operator.body`."""
    run = scenario.run
    busy = body_script.busy_until if isinstance(body_script, KnowsWhenFree) else None
    person = builder.AddNamedSystem(
        "operator",
        SimulatedOperator(operator, scenario.motion.hold_time, run.period, busy, run.handover_time),
    )
    builder.ExportInput(person.GetInputPort("hri.prompt"), "hri.prompt")
    builder.ExportOutput(person.GetOutputPort("hri.indication"), "hri.indication")
    if not scenario.body.enabled:
        tracker = builder.AddNamedSystem(
            "body_tracker", ConstantValueSource(AbstractValue.Make(NOBODY))
        )
        builder.ExportOutput(tracker.get_output_port(), "operator.body")
        return person
    body = builder.AddNamedSystem(
        "operator_body",
        OperatorBody(scene_graph, plant, parts, scenario.body, run.period, body_script),
    )
    builder.Connect(
        body.GetOutputPort("geometry_pose"), scene_graph.get_source_pose_port(body.source_id)
    )
    builder.Connect(plant.get_body_poses_output_port(), body.GetInputPort("body_poses"))
    builder.Connect(person.GetOutputPort("activity"), body.GetInputPort("activity"))
    spheres = body.GetOutputPort("spheres")
    if injector is not None and injector.has_tracker_loss:
        builder.Connect(spheres, injector.GetInputPort("operator.body"))
        tracked = injector.GetOutputPort("operator.body")
        export_measured(builder, tracked, "operator.body", scenario, truth=spheres)
    else:
        export_measured(builder, spheres, "operator.body", scenario)
    return person


# A part slower than this rests (a bolt takes where it rests).
REST_SPEED = 0.001  # m/s


class RestingParts(LeafSystem):
    """Sim only: the parts at rest (slower than REST_SPEED) and out of the gripper (no finger
    touches them), for the simulated operator's bolts. Inputs: `contact_results`,
    `body_spatial_velocities` (the plant's). Output: `resting` (frozenset of part instances)."""

    def __init__(self, plant: MultibodyPlant, parts: Mapping[str, object]):
        super().__init__()
        self._bodies = {name: int(plant.GetBodyIndices(model)[0]) for name, model in parts.items()}
        self._owners = geometry_owners(plant)
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self._velocities = self.DeclareAbstractInputPort(
            "body_spatial_velocities", AbstractValue.Make([SpatialVelocity()])
        )
        self.DeclareAbstractOutputPort(
            "resting", lambda: AbstractValue.Make(frozenset()), self._calc
        )

    def _calc(self, context, output) -> None:
        held = set()
        for a, b in owner_pairs(self._contacts.Eval(context), self._owners):
            if a.model == GRIPPER:
                held.add(b.model)
            elif b.model == GRIPPER:
                held.add(a.model)
        velocities = self._velocities.Eval(context)
        output.set_value(
            frozenset(
                name
                for name, body in self._bodies.items()
                if name not in held
                and np.linalg.norm(velocities[body].translational()) < REST_SPEED
            )
        )


def _add_camera(builder: DiagramBuilder, scene_graph, config: CameraConfig, port: str) -> None:
    """An RGB camera described by a Drake `CameraConfig`; its image renders only when `port`
    is evaluated (a still), as the sensor is built from the config (`MakeCameras`) rather than
    `ApplyCameraConfig`, which would also publish every frame on LCM."""
    if not scene_graph.HasRenderer(config.renderer_name):
        params = RenderEngineVtkParams()
        scene_graph.AddRenderer(config.renderer_name, MakeRenderEngineVtk(params))
    color, depth = config.MakeCameras()
    sensor = builder.AddNamedSystem(
        config.name,
        RgbdSensor(scene_graph.world_frame_id(), config.X_PB.GetDeterministicValue(), color, depth),
    )
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    builder.ExportOutput(sensor.color_image_output_port(), port)


def _add_faults(builder: DiagramBuilder, plant: MultibodyPlant, scenario: Scenario, seats):
    """The fault injector (it passes everything through when the scenario has no faults):
    `safety.stop` out, the pushes on the plant's joints, the obstacle's servo target (when the
    plant has the obstacle), `sim.faults` (what it injected). `seats`: a SeatPositions."""
    faults = builder.AddNamedSystem(
        "fault_injector",
        FaultInjector(
            plant,
            scenario.faults,
            scenario.run.period,
            seats,
            [u.name for u in scenario.safety.sensor.units],
        ),
    )
    for name in (OBSTACLE, DEBRIS):
        if plant.HasModelInstanceNamed(name):
            builder.Connect(
                faults.GetOutputPort(name),
                plant.get_desired_state_input_port(plant.GetModelInstanceByName(name)),
            )
    builder.ExportOutput(faults.GetOutputPort("injected"), "sim.faults")
    builder.Connect(
        faults.GetOutputPort("torque"), plant.get_applied_generalized_force_input_port()
    )
    return faults


def _export_disturbance(builder: DiagramBuilder, plant: MultibodyPlant) -> None:
    # A station without the robot: a disturbance on the plant's joints; unconnected, none.
    builder.ExportInput(
        plant.get_applied_generalized_force_input_port(), "sim.applied_generalized_force"
    )


def _export_sim_ports(builder: DiagramBuilder, plant: MultibodyPlant, scene_graph) -> None:
    builder.ExportOutput(plant.get_state_output_port(), "sim.plant_state")
    builder.ExportOutput(plant.get_contact_results_output_port(), "sim.contact_results")
    builder.ExportOutput(plant.get_body_poses_output_port(), "sim.body_poses")
    builder.ExportOutput(scene_graph.get_query_output_port(), "sim.query_object")


def _add_part_sensors(builder, plant, scene_graph, frames, parts, person, scenario) -> None:
    """The configuration sensor (exported as `configuration`: the contact sensor's reading, or
    a camera's, `export_configuration`) and, for the simulated operator only, which parts rest
    out of the gripper (a bolt takes once its part rests)."""
    sensor = builder.AddNamedSystem("configuration_sensor", SlotMonitor(plant, scene_graph, frames))
    builder.Connect(plant.get_contact_results_output_port(), sensor.GetInputPort("contact_results"))
    builder.Connect(plant.get_body_poses_output_port(), sensor.GetInputPort("body_poses"))
    builder.Connect(scene_graph.get_query_output_port(), sensor.GetInputPort("query_object"))
    export_configuration(builder, sensor, plant, scenario)
    builder.ExportOutput(sensor.GetOutputPort("held_part"), "sim.held_part")
    # The simulated operator bolts where the part truly sits: the contact sensor's reading.
    builder.Connect(
        sensor.GetOutputPort("slot_configuration"), person.GetInputPort("configuration")
    )
    resting = builder.AddNamedSystem("resting_parts", RestingParts(plant, parts))
    builder.Connect(
        plant.get_contact_results_output_port(), resting.GetInputPort("contact_results")
    )
    builder.Connect(
        plant.get_body_spatial_velocities_output_port(),
        resting.GetInputPort("body_spatial_velocities"),
    )
    builder.Connect(resting.GetOutputPort("resting"), person.GetInputPort("resting"))


def make_cell_station(
    scenario: Scenario,
    meshcat: Meshcat | None = None,
    *,
    design: CellDesign | None = None,
    space: StateSpace | None = None,
    arm_start: Sequence[float] | None = None,
    camera: bool | None = None,
    operator: Operator | None = None,
    body_script: BodyScript | None = None,
) -> CellStation:
    """Build the station of `scenario` (see the module docstring).

    What a run has already built is handed in, not built again: the cell `design` and the
    state `space` of its spec (default: from `scenario.assembly`). `arm_start` is where the
    arm starts [rad] (default: `station.ur3.initial_positions`, else the ready posture; a run
    starts it at the planner's home); `camera` whether the still camera is built (default:
    the scenario's `cameras`, if any; True with none given: the operator's view). `operator`
    answers the interface's prompts (default: the scenario's operator); `body_script` moves
    the operator's body (default: `BoltingScript`).
    With `meshcat` a visualizer draws the cell there (and records, if asked). CellModelError
    (before anything is simulated) if the spec does not fit the cell; ValueError naming the
    scenario key for a bad station value."""
    if design is None:
        design = cell_design(scenario, load_spec(scenario.assembly_path))
    check_station_scenario(scenario, design)
    if space is None:
        space = generate_states(design.spec)
    operator = _station_operator(scenario, space, operator)
    builder = DiagramBuilder()
    plant, scene_graph, instances, bolts, frames = _add_plant(builder, scenario, design, arm_start)
    injector = _add_robot(builder, plant, instances, scenario, frames, space)
    parts = {name: instances[name] for name in design.instance_names}
    if scenario.body.enabled:
        add_bins(scene_graph, design.layout)
    body_script = body_script_of(scenario, frames, body_script)
    person = _add_operator(
        builder, plant, scene_graph, parts, scenario, operator, body_script, injector
    )
    if injector is not None:  # it counts tasks from the prompts the station shows
        builder.ConnectInput("hri.prompt", injector.GetInputPort("hri.prompt"))
    _add_part_sensors(builder, plant, scene_graph, frames, parts, person, scenario)
    if scenario.station.robot:
        _connect_safety_function(builder, plant, scene_graph, instances, scenario, frames)
    builder.ExportOutput(person.GetOutputPort("bolts"), "sim.welds")
    _export_sim_ports(builder, plant, scene_graph)
    visualizer = _add_viewers(builder, scene_graph, scenario, camera, meshcat)
    diagram = builder.Build()
    diagram.set_name("cell_station")
    return CellStation(
        diagram, plant, scene_graph, scenario, design, frames, instances, bolts, meshcat,
        visualizer, injector, person,
    )  # fmt: skip


def _add_robot(builder, plant, instances, scenario: Scenario, frames, space: StateSpace):
    """The arm's servo and the gripper's ports, with the scenario's fault injector between
    them and the plant (returned; None without faults); without a robot, the plant's
    disturbance input exported instead."""
    if not scenario.station.robot:
        _export_disturbance(builder, plant)
        return None
    function = _add_arm(builder, plant, instances[UR3], scenario, frames)
    injector = _add_faults(builder, plant, scenario, SeatPositions(frames, space))
    builder.Connect(injector.GetOutputPort("safety.stop"), function.GetInputPort("external_stop"))
    add_gripper_ports(
        builder,
        plant,
        instances[GRIPPER],
        scenario.station.rg2.kp,
        injector,
        lambda port, name: export_measured(builder, port, name, scenario),
    )
    return injector


def _connect_safety_function(builder, plant, scene_graph, instances, scenario, frames) -> None:
    """The safety function's measurements: the gripper's opening and the body as its safety
    sensor sees it (`safety.sensor`; off, the simulated body itself)."""
    function = builder.GetSubsystemByName("safety_function")
    gripper = builder.GetSubsystemByName("rg2_measure").get_output_port(0)
    builder.Connect(gripper, function.GetInputPort("rg2.state"))
    person = (
        builder.GetSubsystemByName("operator_body").GetOutputPort("spheres")
        if builder.HasSubsystemNamed("operator_body")
        else None
    )
    sensor = add_safety_sensor(builder, plant, scene_graph, instances, scenario, frames, person)
    if sensor is not None:
        silent = sensor.GetInputPort("safety_sensor.silent")
        injector = builder.GetSubsystemByName("fault_injector")
        if injector.has_silent_sensor:
            builder.Connect(injector.GetOutputPort("safety_sensor.silent"), silent)
        else:  # a test may silence a unit
            builder.ExportInput(silent, "sim.safety_sensor.silent")
        builder.ExportOutput(sensor.GetOutputPort("safety_sensor.body"), "sim.safety_sensor.body")
        return
    tracker = person or builder.GetSubsystemByName("body_tracker").get_output_port()
    builder.Connect(tracker, function.GetInputPort("operator.body"))


def _add_viewers(builder, scene_graph, scenario: Scenario, camera: bool | None, meshcat):
    """The scenario's cameras (`cameras`; with `camera` True and none given, the operator's
    view; with `camera` False, none) and, with `meshcat`, a visualizer drawing the cell there
    (returned; else None). The first camera's image is `sim.camera.rgb_image`, any other's
    `sim.camera.NAME.rgb_image`."""
    cameras = cell_configs(scenario).cameras if camera is not False else []
    if camera and not cameras:
        cameras = [OPERATOR_VIEW]
    for index, config in enumerate(cameras):
        port = "sim.camera.rgb_image" if index == 0 else f"sim.camera.{config.name}.rgb_image"
        _add_camera(builder, scene_graph, config, port)
    if meshcat is None:
        return None
    params = MeshcatVisualizerParams(delete_on_initialization_event=False)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def _station_operator(scenario: Scenario, space, operator: Operator | None) -> Operator:
    """Who answers the prompts: `operator`, else the scenario's; slowed by the scenario's
    `operator-silent` and `no-path` faults, if any."""
    if operator is None:
        operator = scenario.operator_for(space)
    if any(f.kind in SilentOperator.KINDS for f in scenario.faults):
        operator = SilentOperator(operator, scenario.faults)
    return operator


def simulate_station(
    station: CellStation,
    context: Context | None = None,
    duration: float = 0.5,
    recording: str | Path | None = None,
) -> Simulator:
    """Simulate the station alone for `duration` seconds from `context` (default: a fresh
    `create_default_context()`, the robot holding still); with Meshcat, record the run and save
    it as HTML at `recording`. Returns the simulator."""
    context = context if context is not None else station.create_default_context()
    if recording is not None and station.meshcat is None:
        raise ValueError("a recording needs Meshcat: pass one to make_cell_station")
    simulator = make_simulator(station.scenario, station.diagram, context)
    if recording is not None:
        station.visualizer.StartRecording()
    simulator.AdvanceTo(context.get_time() + duration)
    if recording is not None:
        station.visualizer.StopRecording()
        station.visualizer.PublishRecording()
        atomic_write_text(recording, station.meshcat.StaticHtml())
    return simulator


def station_scenario(scenario: Scenario, **station) -> Scenario:
    """A copy of `scenario` whose `station:` section has the fields given (e.g.
    `station_scenario(s, robot=False, initial_placements={...})`)."""
    return dataclasses.replace(scenario, station=dataclasses.replace(scenario.station, **station))


__all__ = [
    "check_station_scenario",
    "make_cell_station",
    "simulate_station",
    "station_scenario",
]
