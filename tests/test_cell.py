"""The cell in Drake: models, diagram, and the SlotMonitor read from physics."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.parsing import PackageMap
from pydrake.multibody.plant import MultibodyPlant
from pydrake.solvers import Solve

from hrc_drake.cell.controller.build import COMMANDED, MEASURED, PENDANT, WATCHDOG
from hrc_drake.cell.ports import PartStatus
from hrc_drake.cell.scenario import load_cell_scenario, plant_config, scene_graph_config
from hrc_drake.cell.station import make_cell_station, simulate_station, station_scenario
from hrc_drake.cell.station.sim_operator import bolt_weld
from hrc_drake.cell.station.welds import Weld
from hrc_drake.cell_models import CellDesign, CellModelError, add_cell_models
from hrc_drake.hri.messages import Indication
from hrc_drake.motion.poses import default_layout, tcp_pose
from hrc_drake.resources import models_dir
from hrc_drake.robot_models import RG2_JOINTS, add_robot, make_parser, set_rg2_opening
from hrc_drake.scenario.schema import Scenario, ScenarioError
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.workpiece_sdf import PLATE

PARTS = ("oval_flange_1", "oval_flange_2", "square_flange")
SETTLE = 0.5
# What only the simulator offers (docs/station.md); the controller never reads these.
SIM_PORTS = (
    "sim.welds",
    "sim.plant_state",
    "sim.contact_results",
    "sim.body_poses",
    "sim.query_object",
)

# Table 1 of the paper, one row per distinct configuration (flange-case.md; states 17-20 repeat
# 11, 12, 9, 10 in another order).
TABLE_1_CONFIGURATIONS = [
    frozenset(c)
    for c in (
        (),
        ("F1",),
        ("F2",),
        ("F3",),
        ("S12",),
        ("S23",),
        ("F1", "S23"),
        ("F3", "S12"),
        ("F1", "S23", "F02"),
        ("F1", "S23", "F03"),
        ("F3", "S12", "F01"),
        ("F3", "S12", "F02"),
        ("S12", "F01"),
        ("S12", "F02"),
        ("S23", "F02"),
        ("S23", "F03"),
    )
]


def _workpieces(**station) -> Scenario:
    """The default scenario with a station of the workpieces only (and `station` fields)."""
    return station_scenario(Scenario(), robot=False, **station)


@pytest.fixture(scope="module")
def workcell():
    return make_cell_station(_workpieces())


@pytest.fixture(scope="module")
def cell():
    return make_cell_station(Scenario())


def _perturbed(X: RigidTransform, rng: np.random.Generator, lift: float) -> RigidTransform:
    """A few mm above the seat, under 1 mm off, tilted under 1°: a part let go near its seat."""
    dx, dy = rng.uniform(-0.0008, 0.0008, size=2)
    roll, pitch, yaw = rng.uniform(-math.radians(1), math.radians(1), size=3)
    return X @ RigidTransform(RollPitchYaw(roll, pitch, yaw), [dx, dy, lift])


def _set_parts(station, context, poses: dict[str, RigidTransform]) -> None:
    plant_context = station.plant.GetMyContextFromRoot(context)
    for part, X_WP in poses.items():
        station.plant.SetFreeBodyPose(plant_context, station.part_body(part), X_WP)


def test_every_model_parses_offline():
    files = sorted((models_dir() / "cell").glob("*.sdf"))
    assert {f.name for f in files} >= {"table.sdf"}
    for path in files:
        plant = MultibodyPlant(0.0)
        parser = make_parser(plant)
        assert isinstance(parser.package_map(), PackageMap)
        assert parser.AddModels(str(path)), path
    # The workpieces are generated from every assembly spec and parse the same way.
    for spec_file in sorted((models_dir() / "assemblies").glob("*.yaml")):
        plant = MultibodyPlant(0.0)
        instances = add_cell_models(plant, CellDesign.of(load_spec(spec_file)))
        plant.Finalize()
        assert {"base_plate", "tray", "table", "ur3", "rg2"} <= set(instances), spec_file


def test_models_carry_the_convention_frames(workcell):
    plant = workcell.plant
    for k in (1, 2, 3):
        assert plant.HasFrameNamed(f"slot_{k}", workcell.instances["base_plate"])
    for j in (1, 2):
        assert plant.HasFrameNamed(f"row_{j}", workcell.instances["square_flange"])
    for part in PARTS:
        assert plant.HasFrameNamed("grasp", workcell.instances[part])
        assert plant.HasFrameNamed(f"home_{part}", workcell.instances["tray"])


def _port_names(diagram, inputs: bool) -> set[str]:
    if inputs:
        return {diagram.get_input_port(i).get_name() for i in range(diagram.num_input_ports())}
    return {diagram.get_output_port(i).get_name() for i in range(diagram.num_output_ports())}


def test_whole_cell_builds_with_ports_and_constraints(cell, workcell):
    diagram = cell.diagram
    # The ports of docs/station.md: exactly what a controller commands and what a real cell
    # measures, and beside them only the simulator's own (`sim.*`).
    inputs, outputs = _port_names(diagram, inputs=True), _port_names(diagram, inputs=False)
    assert {n for n in inputs if not n.startswith("sim.")} == {*COMMANDED, *PENDANT, *WATCHDOG}
    # Beside them, what its servo followed (RTDE's `target_q`), one of the `LINK_READINGS`.
    assert {n for n in outputs if not n.startswith("sim.")} == {*MEASURED, "ur3.target"}
    assert set(SIM_PORTS) <= outputs
    for name, size in (
        ("ur3.position", 6),
        ("ur3.velocity", 6),
        ("rg2.opening", 1),
        ("rg2.force", 1),
    ):
        assert diagram.GetInputPort(name).size() == size, name
    for name, size in (("ur3.state_estimated", 12), ("rg2.state_measured", 2)):
        assert diagram.GetOutputPort(name).size() == size, name
    assert diagram.GetOutputPort("rg2.grip_detected").size() == 1
    # What each part may be bolted to: the ovals to the plate or the square's rows, the square
    # to the plate. No grasp welds: the fingers hold by friction; the only constraints are the
    # gripper linkage's couplers.
    assert dict(cell.bolts.supports) == {
        "oval_flange_1": (PLATE, "square_flange"),
        "oval_flange_2": (PLATE, "square_flange"),
        "square_flange": (PLATE,),
    }
    assert cell.bolts.holds(Weld("oval_flange_1", "square_flange/row_2"))
    assert not cell.bolts.holds(Weld("square_flange", "square_flange/row_1"))
    assert cell.plant.num_constraints() == len(RG2_JOINTS) - 1
    context = cell.create_default_context()
    plant_context = cell.plant.GetMyContextFromRoot(context)
    assert cell.bolts.bolted(plant_context) == set()
    assert cell.wanted_welds(context) == frozenset()
    # The default context: the arm at the scenario's ready posture, at rest, the fingers at
    # the initial opening, on nothing; the operator has said nothing.
    station = cell.scenario.station
    measured = diagram.GetOutputPort("ur3.state_estimated").Eval(context)
    np.testing.assert_allclose(measured, [*station.ur3.ready, *[0.0] * 6])
    gripper = diagram.GetOutputPort("rg2.state_measured").Eval(context)
    np.testing.assert_allclose(gripper, [station.rg2.initial_opening, 0.0], atol=1e-12)
    assert diagram.GetOutputPort("rg2.grip_detected").Eval(context)[0] == 0.0
    assert diagram.GetOutputPort("hri.indication").Eval(context) == Indication()
    # The workpieces-only station has no robot ports.
    robot_inputs = {"ur3.position", "ur3.velocity", "rg2.opening", "rg2.force"}
    assert not robot_inputs & _port_names(workcell.diagram, inputs=True)
    assert "hri.prompt" in _port_names(workcell.diagram, inputs=True)
    assert dict(workcell.bolts.supports) == dict(cell.bolts.supports)


def test_no_penetration_at_the_initial_state(cell):
    context = cell.create_default_context()
    query = cell.diagram.GetOutputPort("sim.query_object").Eval(context)
    inspector = cell.scene_graph.model_inspector()

    def model(gid):
        return inspector.GetName(gid).split("::")[0]

    unexpected = []
    for pair in query.ComputePointPairPenetration():
        models = {model(pair.id_A), model(pair.id_B)}
        resting = "tray" in models and models & set(PARTS)
        if not (resting and pair.depth < 1e-4):
            unexpected.append(
                (inspector.GetName(pair.id_A), inspector.GetName(pair.id_B), pair.depth)
            )
    assert unexpected == []
    configuration = cell.configuration(context)
    assert all(configuration.status(p) is PartStatus.TRAY for p in PARTS)
    assert configuration.tokens() == frozenset()


def test_the_sixteen_configurations_are_those_of_table_1():
    assert sorted(map(sorted, generate_states(load_spec()).configurations())) == sorted(
        map(sorted, TABLE_1_CONFIGURATIONS)
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "configuration", TABLE_1_CONFIGURATIONS, ids=lambda c: "+".join(sorted(c)) or "empty"
)
def test_settled_configuration_is_read_from_physics(workcell, configuration):
    rng = np.random.default_rng(sorted(TABLE_1_CONFIGURATIONS, key=sorted).index(configuration))
    placements = default_layout(workcell.frames, configuration)
    seated = workcell.placement_poses(placements)
    spec = workcell.design.spec
    poses = {
        part: _perturbed(X, rng, lift=0.006 if spec.placement(placements[part]).host else 0.003)
        for part, X in seated.items()
    }
    context = workcell.create_default_context()
    _set_parts(workcell, context, poses)
    simulate_station(workcell, context, SETTLE)
    reading = workcell.configuration(context)
    assert reading.tokens() == configuration
    station_context = workcell.diagram.GetMyContextFromRoot(context)
    assert workcell.diagram.GetOutputPort("sim.held_part").Eval(station_context) == ""
    for part in PARTS:
        expected = PartStatus.SEATED if part in placements else PartStatus.TRAY
        assert reading.status(part) is expected, part


@pytest.mark.slow
def test_straddling_flange_is_misplaced(workcell):
    X_W_slot1, X_W_slot2 = (
        workcell.plant.GetFrameByName(f"slot_{k}").CalcPoseInWorld(
            workcell.plant.CreateDefaultContext()
        )
        for k in (1, 2)
    )
    between = RigidTransform(
        X_W_slot1.rotation(), (X_W_slot1.translation() + X_W_slot2.translation()) / 2
    )
    context = workcell.create_default_context()
    _set_parts(
        workcell, context, {"oval_flange_1": _perturbed(between, np.random.default_rng(7), 0.003)}
    )
    simulate_station(workcell, context, SETTLE)
    reading = workcell.configuration(context)
    assert reading.status("oval_flange_1") is PartStatus.MISPLACED
    assert reading.tokens() == frozenset()


@pytest.mark.parametrize("modulus", [5e6, 1e7])
def test_a_flange_dropped_across_a_pocket_rests_on_its_rims_at_either_modulus(modulus):
    """A part that falls out of the gripper turned across a pocket lands on the rims, whatever
    the modulus; with a boss's collision box only its 4.5 mm height (hrc_drake.workpiece_sdf)
    its boss sank between the rims and stayed wedged there by kilonewtons of balanced contact
    force, which no grasp lifts (the first and the sixth of these drops, at 1e7 Pa; the first
    at 5e6 Pa)."""
    material = f"{{hydroelastic_modulus: {modulus:g}}}"
    text = f"{{scene_graph_config: {{default_proximity_properties: {material}}}}}"
    station = make_cell_station(station_scenario(load_cell_scenario(None, [text]), robot=False))
    plant, body = station.plant, station.part_body("oval_flange_1")
    X_W_slot = plant.GetFrameByName("slot_1").CalcPoseInWorld(plant.CreateDefaultContext())
    weight = body.default_mass() * 9.81
    part_geometries = set(plant.GetCollisionGeometriesForBody(body))
    rng = np.random.default_rng(0)
    for drop in range(6):
        yaw, speed = rng.uniform(0.6, math.pi / 2), rng.uniform(0.5, 1.2)
        (dx, dy), tilt = rng.uniform(-0.01, 0.01, 2), rng.uniform(-0.1, 0.1)
        context = station.create_default_context()
        plant_context = plant.GetMyContextFromRoot(context)
        X_drop = X_W_slot @ RigidTransform(RollPitchYaw(tilt, 0, yaw), [dx, dy, 0.006])
        plant.SetFreeBodyPose(plant_context, body, X_drop)
        plant.SetFreeBodySpatialVelocity(
            plant_context, body, SpatialVelocity([0, 0, 0], [0, 0, -speed])
        )
        simulate_station(station, context, 1.0)
        rest = X_W_slot.InvertAndCompose(plant.EvalBodyPoseInWorld(plant_context, body))
        contacts = plant.get_contact_results_output_port().Eval(plant_context)
        infos = map(contacts.hydroelastic_contact_info, range(contacts.num_hydroelastic_contacts()))
        largest = max(
            np.linalg.norm(info.F_Ac_W().translational())
            for info in infos
            if {info.contact_surface().id_M(), info.contact_surface().id_N()} & part_geometries
        )
        # On the rims: the boss (4.5 mm) stands on the plate's top, 4 mm above the seat floor.
        assert rest.translation()[2] > 0.002, (drop, rest.translation())
        assert largest < 5 * weight, (drop, largest)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("offset", "seated"),
    [
        # In the pocket's corner, turned: as far off as the 1.5 mm clearance lets a part sit.
        (RigidTransform(RollPitchYaw(0, 0, 0.05), [0.0014, 0.0014, 0.001]), True),
        # Beside the pocket: its boss stands on the plate, a pocket's depth high.
        (RigidTransform([0.0, 0.025, 0.001]), False),
    ],
)
def test_a_part_is_seated_exactly_when_it_sits_in_its_pocket(workcell, offset, seated):
    """The seat tolerances are what the pocket's clearance allows."""
    X_W_seat = workcell.placement_poses({"oval_flange_1": "F2"})["oval_flange_1"]
    context = workcell.create_default_context()
    _set_parts(workcell, context, {"oval_flange_1": X_W_seat @ offset})
    simulate_station(workcell, context, SETTLE)
    reading = workcell.configuration(context)
    expected = PartStatus.SEATED if seated else PartStatus.MISPLACED
    assert reading.status("oval_flange_1") is expected
    assert reading.tokens() == ({"F2"} if seated else frozenset())


@pytest.mark.slow
def test_a_bolt_fixes_a_part_where_it_sits_not_at_its_seat(workcell):
    """Parts resting off their nominal seats (within the pocket's clearance) are bolted: each
    stays where it sat, within 0.1 mm, and the sensor still reads them seated (their contact
    with their seats is filtered out while bolted)."""
    offsets = {
        "square_flange": RigidTransform(RollPitchYaw(0, 0, 0.02), [0.0010, -0.0006, 0.0]),
        "oval_flange_1": RigidTransform(RollPitchYaw(0, 0, -0.03), [-0.0009, 0.0007, 0.0]),
        "oval_flange_2": RigidTransform(RollPitchYaw(0, 0, 0.04), [0.0008, 0.0008, 0.0]),
    }
    placements = {"square_flange": "S12", "oval_flange_1": "F3", "oval_flange_2": "F01"}
    seated = workcell.placement_poses(placements)
    context = workcell.create_default_context()
    _set_parts(workcell, context, {p: X @ offsets[p] for p, X in seated.items()})
    simulate_station(workcell, context, SETTLE)
    assert workcell.configuration(context).tokens() == {"S12", "F3", "F01"}
    plant = workcell.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)

    def pose(part):
        return plant.EvalBodyPoseInWorld(plant_context, workcell.part_body(part))

    before = {p: pose(p) for p in placements}
    # The bolts the simulated operator puts in: in the seat the sensor reads each part in.
    configuration = workcell.configuration(context)
    bolts = {bolt_weld(configuration, p) for p in placements}
    assert Weld("oval_flange_2", "square_flange/row_1") in bolts
    filters = workcell.scene_graph.collision_filter_manager(
        workcell.scene_graph.GetMyMutableContextFromRoot(context)
    )
    workcell.bolts.apply(plant_context, bolts, filters)
    assert workcell.bolts.bolted(plant_context) == set(placements)
    simulate_station(workcell, context, SETTLE)
    for part, X in before.items():
        moved = X.InvertAndCompose(pose(part))
        assert np.linalg.norm(moved.translation()) < 1e-4, part
        assert moved.rotation().ToAngleAxis().angle() < 1e-3, part
    # Not pulled to the nominal seats: the parts rested up to about a millimetre off them,
    # and stay there.
    off = [np.linalg.norm(seated[p].InvertAndCompose(pose(p)).translation()[:2]) for p in before]
    assert max(off) > 0.0007
    assert workcell.configuration(context).tokens() == {"S12", "F3", "F01"}
    # Unbolted, the parts are free again and rest on their seats by contact.
    workcell.bolts.apply(plant_context, set(), filters)
    assert workcell.bolts.bolted(plant_context) == set()
    simulate_station(workcell, context, SETTLE)
    assert workcell.configuration(context).tokens() == {"S12", "F3", "F01"}
    for part, X in before.items():
        assert np.linalg.norm(X.InvertAndCompose(pose(part)).translation()) < 1e-4, part


def _arm_posture_with_tcp_at(X_W_tcp: RigidTransform) -> np.ndarray:
    """UR3 joint positions putting the gripper's tcp at `X_W_tcp` (IK on the robot alone)."""
    plant = MultibodyPlant(0.0)
    ur3, rg2 = add_robot(plant)
    plant.Finalize()
    ik = InverseKinematics(plant)
    tcp = plant.GetFrameByName("tcp", rg2)
    p = X_W_tcp.translation()
    ik.AddPositionConstraint(tcp, np.zeros(3), plant.world_frame(), p, p)
    ik.AddOrientationConstraint(
        tcp, RotationMatrix(), plant.world_frame(), X_W_tcp.rotation(), 1e-4
    )
    guess = plant.CreateDefaultContext()
    plant.SetPositions(guess, ur3, Scenario().station.ur3.ready)
    ik.get_mutable_prog().SetInitialGuess(ik.q(), plant.GetPositions(guess))
    result = Solve(ik.prog())
    assert result.is_success()
    return result.GetSolution(ik.q())[:6]


def _hold_above_slot_2(cell, part: str, force: float | None = None, lift: float = 0.0015):
    """The gripper closed on `part` `lift` above slot 2 (1.5 mm: boss inside the pocket, clear
    of its floor), commanded 2 mm past the part's width with `force` (default: the
    scenario's), simulated SETTLE s; (root context, the part's pose at the start)."""
    plant = cell.plant
    default = plant.CreateDefaultContext()
    X_W_slot2 = plant.GetFrameByName("slot_2").CalcPoseInWorld(default)
    X_W_part = X_W_slot2 @ RigidTransform([0, 0, lift])
    q = _arm_posture_with_tcp_at(tcp_pose(cell.frames, part, X_W_part))
    context = cell.create_default_context()
    plant_context = plant.GetMyContextFromRoot(context)
    plant.SetPositions(plant_context, cell.instances["ur3"], q)
    width = cell.frames.widths[part]
    set_rg2_opening(plant, plant_context, width)
    plant.SetFreeBodyPose(plant_context, cell.part_body(part), X_W_part)
    cell.hold_robot(context, opening=width - 0.002, force=force)
    simulate_station(cell, context, SETTLE)
    return context, X_W_part


@pytest.mark.slow
def test_held_flange_above_the_plate_is_held_not_seated(cell):
    part = "oval_flange_1"
    # The fingers stall on the part and hold it by friction alone, its boss in the pocket but
    # clear of the floor: held, not seated.
    context, X_W_part = _hold_above_slot_2(cell, part)
    station_context = cell.diagram.GetMyContextFromRoot(context)
    assert cell.diagram.GetOutputPort("rg2.grip_detected").Eval(station_context)[0] == 1.0
    reading = cell.configuration(context)
    assert reading.status(part) is PartStatus.HELD
    assert reading.tokens() == frozenset()
    # The safety check's cheaper truth reads the same part in the gripper.
    assert cell.diagram.GetOutputPort("sim.held_part").Eval(station_context) == part
    plant_context = cell.plant.GetMyContextFromRoot(context)
    drift = X_W_part.InvertAndCompose(
        cell.plant.EvalBodyPoseInWorld(plant_context, cell.part_body(part))
    )
    assert np.linalg.norm(drift.translation()) < 0.001
    # The wrist feels the held part's weight, straight down, and no moment about the tcp to
    # speak of (the part hangs under it): the load the guarded descent zeroes.
    load = cell.diagram.GetOutputPort("ur3.tcp_force").Eval(station_context)
    weight = cell.part_body(part).default_mass() * 9.81
    assert load[2] == pytest.approx(-weight, rel=0.02)
    assert np.abs(load[:2]).max() < 0.02 * weight and np.abs(load[3:]).max() < 0.01


@pytest.mark.slow
def test_a_part_seated_in_the_fingers_is_seated_not_held(cell):
    # The robot holds a part on its seat while the operator bolts it: seated, and the safety
    # check's `sim.held_part` reads no part in the gripper, as the configuration does.
    part = "oval_flange_1"
    context, _ = _hold_above_slot_2(cell, part, lift=0.0)
    station_context = cell.diagram.GetMyContextFromRoot(context)
    assert cell.diagram.GetOutputPort("rg2.grip_detected").Eval(station_context)[0] == 1.0
    reading = cell.configuration(context)
    assert reading.status(part) is PartStatus.SEATED
    assert reading.held() is None
    assert cell.diagram.GetOutputPort("sim.held_part").Eval(station_context) == ""


@pytest.mark.slow
@pytest.mark.parametrize("force", [5.0, 30.0])
def test_the_fingers_squeeze_with_the_commanded_force(cell, force):
    """The RG2 servo is force-limited: fingers stalled on a part push with the commanded
    force, whatever the target past it (here 1 mm past each side)."""
    context, _ = _hold_above_slot_2(cell, "oval_flange_1", force)
    results = cell.diagram.GetOutputPort("sim.contact_results").Eval(
        cell.diagram.GetMyContextFromRoot(context)
    )
    inspector = cell.scene_graph.model_inspector()
    plant_context = cell.plant.GetMyContextFromRoot(context)
    rg2 = cell.instances["rg2"]
    squeeze = {}
    for i in range(results.num_hydroelastic_contacts()):
        info = results.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        for gid, sign in ((surface.id_M(), 1.0), (surface.id_N(), -1.0)):
            body = cell.plant.GetBodyFromFrameId(inspector.GetFrameId(gid))
            if body.model_instance() == rg2 and body.name().endswith("finger"):
                # The force on the finger (F_Ac_W acts on M), along its closing direction.
                X_W_finger = cell.plant.EvalBodyPoseInWorld(plant_context, body)
                y = X_W_finger.rotation().col(1) * (1.0 if body.name() == "left_finger" else -1.0)
                f = sign * info.F_Ac_W().translational()
                squeeze[body.name()] = squeeze.get(body.name(), 0.0) + float(f @ y)
    assert set(squeeze) == {"left_finger", "right_finger"}
    for name, newtons in squeeze.items():
        assert newtons == pytest.approx(force, rel=0.05), name


def test_scenario_yaml_is_typed_and_checked():
    scenario = load_cell_scenario(None, "plant_config: {time_step: 0.002}")
    assert plant_config(scenario).time_step == 0.002
    assert plant_config(scenario).discrete_contact_approximation == "sap"
    with pytest.raises(ScenarioError, match="time_stp"):
        load_cell_scenario(None, "plant_config: {time_stp: 0.002}")
    # The contact material is the scenario's, handed to SceneGraph as its defaults.
    soft = load_cell_scenario(
        None, "scene_graph_config: {default_proximity_properties: {hydroelastic_modulus: 1.0e6}}"
    )
    defaults = scene_graph_config(soft).default_proximity_properties
    assert defaults.hydroelastic_modulus == 1.0e6 and defaults.compliance_type == "compliant"
    with pytest.raises(ScenarioError, match="robt"):
        load_cell_scenario(None, "station: {robt: false}")
    with pytest.raises(ScenarioError, match="SAP-family"):
        load_cell_scenario(None, "plant_config: {discrete_contact_approximation: tamsi}")
    placed = load_cell_scenario(None, "station: {robot: false, initial_placements: {flange_9: F1}}")
    with pytest.raises(ValueError, match=r"station\.initial_placements\.flange_9: not a part"):
        make_cell_station(placed)
    with pytest.raises(ValueError, match="'F07' is not a placement"):
        make_cell_station(_workpieces(initial_placements={"oval_flange_1": "F07"}))
    with pytest.raises(ValueError, match="places a S"):
        make_cell_station(_workpieces(initial_placements={"oval_flange_1": "S12"}))
    short = dataclasses.replace(Scenario().station.ur3, initial_positions=[0.0, 1.0])
    with pytest.raises(ValueError, match=r"station\.ur3\.initial_positions: give 6"):
        make_cell_station(station_scenario(Scenario(), ur3=short))


def test_a_spec_that_does_not_fit_the_cell_is_refused(tmp_path):
    spec = load_spec()
    design = CellDesign.of(spec)
    missing = dataclasses.replace(design.layout, part_models={"F": str(tmp_path / "no.sdf")})
    with pytest.raises(CellModelError, match=r"part F: its model file .* does not exist"):
        make_cell_station(dataclasses.replace(_workpieces(), cell=missing))
    with pytest.raises(CellModelError, match=r"cell\.part_models names 'Q'"):
        CellDesign.of(spec, dataclasses.replace(design.layout, part_models={"Q": "x.sdf"}))


def test_initial_placements_seat_the_parts(workcell):
    station = make_cell_station(
        _workpieces(
            initial_placements={
                "square_flange": "S23",
                "oval_flange_2": "F03",
                "oval_flange_1": "F1",
            },
        )
    )
    context = station.create_default_context()
    simulate_station(station, context, 0.1)
    assert station.configuration(context).tokens() == {"S23", "F03", "F1"}
    with pytest.raises(ValueError, match="F01 needs one S over base slot 1"):
        workcell.placement_poses({"oval_flange_1": "F01"})
