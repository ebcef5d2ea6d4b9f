"""The UR3 and RG2 models against the published figures (see the models' source comments)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.geometry import Cylinder, Role
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell.scenario import contact_material, load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.resources import package_uri
from hrc_drake.rg2_kinematics import (
    MAX_ANGLE,
    TCP_HEIGHT,
    URDF_MAX_ANGLE,
    crank_angle,
    opening_at,
    opening_rate,
    pad_height,
)
from hrc_drake.robot_models import (
    RG2_DRIVE_JOINT,
    RG2_JOINTS,
    RG2_MAX_FORCE,
    RG2_MAX_OPENING,
    UR3_EFFORT_LIMITS,
    UR3_SURFACE_RADII,
    add_robot,
    make_parser,
    set_rg2_opening,
)
from hrc_drake.robot_names import UR3_JOINTS, UR3_VELOCITY_LIMITS
from hrc_drake.workpiece_sdf import BOSS_MODULUS_SCALE, is_boss

sys.path.insert(0, str(Path(__file__).parent))
from rg2_sim_device import SimulatedRg2

# Standard DH of the UR3 (CB3), Universal Robots' DH article: (a, d, alpha) per joint.
UR3_DH = (
    (0.0, 0.1519, math.pi / 2),
    (-0.24365, 0.0, 0.0),
    (-0.21325, 0.0, 0.0),
    (0.0, 0.11235, math.pi / 2),
    (0.0, 0.08535, -math.pi / 2),
    (0.0, 0.0819, 0.0),
)
UR3_LINK_MASSES = (2.0, 2.0, 3.42, 1.26, 0.8, 0.8, 0.35)
UR3_LINKS = (
    "base_link_inertia",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
HOME = np.array([0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0])
TOOL_DOWN = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
# ROS's base_link is UR's `base` turned by π about z.
X_BASELINK_URBASE = np.diag([-1.0, -1.0, 1.0, 1.0])


def dh_fk(q: np.ndarray) -> np.ndarray:
    """UR `base` -> DH frame 6 (the tool flange), standard DH: Rz(θ) Tz(d) Tx(a) Rx(α)."""
    X = np.eye(4)
    for theta, (a, d, alpha) in zip(q, UR3_DH, strict=True):
        ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
        X = X @ np.array(
            [
                [ct, -st * ca, st * sa, a * ct],
                [st, ct * ca, -ct * sa, a * st],
                [0.0, sa, ca, d],
                [0.0, 0.0, 0.0, 1.0],
            ]
        )
    return X


def rotation_angle(R1: np.ndarray, R2: np.ndarray) -> float:
    # arcsin of the chordal distance stays accurate for tiny angles, unlike arccos of the trace.
    chord = np.linalg.norm(R1 - R2) / (2 * math.sqrt(2))
    return 2 * math.asin(min(1.0, chord))


def ur3_alone() -> MultibodyPlant:
    plant = MultibodyPlant(0.0)
    parser = make_parser(plant)
    (ur3,) = parser.AddModels(url=package_uri("ur3/ur3.urdf"))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", ur3))
    plant.Finalize()
    return plant


@pytest.fixture(scope="module")
def robot() -> MultibodyPlant:
    plant = MultibodyPlant(0.0)
    add_robot(plant)
    plant.Finalize()
    return plant


def test_dh_reference_check_value() -> None:
    X = dh_fk(np.zeros(6))
    np.testing.assert_allclose(X[:3, 3], [-0.4569, -0.19425, 0.06655], atol=1e-12)


def test_base_link_to_tool0_matches_dh() -> None:
    plant = ur3_alone()
    context = plant.CreateDefaultContext()
    base = plant.GetFrameByName("base_link")
    tool0 = plant.GetFrameByName("tool0")
    rng = np.random.default_rng(20240607)
    qs = [np.zeros(6), HOME, TOOL_DOWN] + [rng.uniform(-math.pi, math.pi, 6) for _ in range(12)]
    worst_p, worst_r = 0.0, 0.0
    for q in qs:
        plant.SetPositions(context, q)
        X_model = plant.CalcRelativeTransform(context, base, tool0).GetAsMatrix4()
        X_dh = X_BASELINK_URBASE @ dh_fk(q)
        worst_p = max(worst_p, float(np.max(np.abs(X_model[:3, 3] - X_dh[:3, 3]))))
        worst_r = max(worst_r, rotation_angle(X_model[:3, :3], X_dh[:3, :3]))
    assert worst_p < 1e-6
    assert worst_r < 1e-6


def test_tool0_at_zero_matches_reference() -> None:
    plant = ur3_alone()
    context = plant.CreateDefaultContext()
    X = plant.CalcRelativeTransform(
        context, plant.GetFrameByName("base_link"), plant.GetFrameByName("tool0")
    )
    np.testing.assert_allclose(X.translation(), [0.4569, 0.19425, 0.06655], atol=1e-9)
    np.testing.assert_allclose(X.rotation().matrix(), [[-1, 0, 0], [0, 0, 1], [0, 1, 0]], atol=1e-9)


def test_ur3_limits_as_published() -> None:
    plant = ur3_alone()
    assert plant.num_actuators() == 6
    for name, vel, effort in zip(UR3_JOINTS, UR3_VELOCITY_LIMITS, UR3_EFFORT_LIMITS, strict=True):
        joint = plant.GetJointByName(name)
        bound = math.pi if name == "elbow_joint" else 2 * math.pi
        np.testing.assert_allclose(joint.position_lower_limits(), [-bound])
        np.testing.assert_allclose(joint.position_upper_limits(), [bound])
        np.testing.assert_allclose(joint.velocity_upper_limits(), [vel])
        np.testing.assert_allclose(joint.velocity_lower_limits(), [-vel])
        actuator = plant.GetJointActuatorByName(name.replace("_joint", "_motor"))
        assert actuator.joint().name() == name
        assert actuator.effort_limit() == pytest.approx(effort)
    assert UR3_VELOCITY_LIMITS[:3] == pytest.approx([math.radians(180)] * 3)
    assert UR3_VELOCITY_LIMITS[3:] == pytest.approx([math.radians(360)] * 3)


def test_ur3_masses_as_published() -> None:
    plant = ur3_alone()
    masses = [plant.GetBodyByName(name).default_mass() for name in UR3_LINKS]
    assert masses == pytest.approx(UR3_LINK_MASSES)
    assert sum(masses) == pytest.approx(10.63)


class RobotScene:
    """UR3 + RG2 from the directives in a diagram with a SceneGraph."""

    def __init__(self) -> None:
        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        self.ur3, self.rg2 = add_robot(self.plant)
        self.plant.Finalize()
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyContextFromRoot(self.context)
        self.inspector = self.scene_graph.model_inspector()

    def set(self, q: np.ndarray, opening: float = RG2_MAX_OPENING) -> None:
        self.plant.SetPositions(self.plant_context, self.ur3, q)
        set_rg2_opening(self.plant, self.plant_context, opening, self.rg2)

    def colliding_pairs(self) -> list[tuple[str, str]]:
        query = self.scene_graph.get_query_output_port().Eval(
            self.scene_graph.GetMyContextFromRoot(self.context)
        )
        frame_name = self.inspector.GetName
        return [
            (
                frame_name(self.inspector.GetFrameId(p.id_A)),
                frame_name(self.inspector.GetFrameId(p.id_B)),
            )
            for p in query.ComputePointPairPenetration()
        ]


@pytest.fixture(scope="module")
def scene() -> RobotScene:
    return RobotScene()


def test_both_models_parse_offline_with_their_actuators(scene: RobotScene) -> None:
    """The RG2 has one motor: one actuator, on the crank, whose effort limit squeezes with the
    RG2's 40 N where the lever is longest (closed); its three other joints follow it."""
    plant = scene.plant
    assert plant.num_actuators(scene.ur3) == 6
    assert plant.num_actuators(scene.rg2) == 1
    assert plant.num_positions() == 6 + len(RG2_JOINTS)
    assert plant.num_constraints() == len(RG2_JOINTS) - 1  # the linkage's couplers
    crank = plant.GetJointByName(RG2_DRIVE_JOINT, scene.rg2)
    np.testing.assert_allclose(crank.position_lower_limits(), [0.0])
    np.testing.assert_allclose(crank.position_upper_limits(), [MAX_ANGLE], atol=1e-4)
    actuator = plant.GetJointActuatorByName(RG2_DRIVE_JOINT, scene.rg2)
    needed = RG2_MAX_FORCE * opening_rate(0.0)
    assert needed <= actuator.effort_limit() <= needed * 1.01


def test_gripper_mass_and_frames(scene: RobotScene) -> None:
    plant, context = scene.plant, scene.plant_context
    rg2_mass = sum(
        plant.get_body(index).default_mass() for index in plant.GetBodyIndices(scene.rg2)
    )
    assert rg2_mass == pytest.approx(0.78)
    scene.set(HOME)
    X_tool0_tcp = plant.CalcRelativeTransform(
        context, plant.GetFrameByName("tool0", scene.ur3), plant.GetFrameByName("tcp", scene.rg2)
    )
    # The tcp is where the RG2's pads are at the oval flanges' 45 mm width.
    np.testing.assert_allclose(X_tool0_tcp.translation(), [0.0, 0.0, TCP_HEIGHT], atol=1e-6)
    np.testing.assert_allclose(X_tool0_tcp.rotation().matrix(), np.eye(3), atol=1e-12)


def _pad_faces(scene: RobotScene) -> dict[str, np.ndarray]:
    """Each finger's pad: the centre of its inside face (toward the other pad), in rg2_base."""
    plant, inspector = scene.plant, scene.inspector
    base = plant.GetFrameByName("rg2_base", scene.rg2)
    faces = {}
    for name, sign in (("left_finger", 1.0), ("right_finger", -1.0)):
        body = plant.GetBodyByName(name, scene.rg2)
        (pad,) = [
            g
            for g in plant.GetCollisionGeometriesForBody(body)
            if inspector.GetName(g).endswith("pad")
        ]
        X = body.body_frame().CalcPose(scene.plant_context, base) @ inspector.GetPoseInFrame(pad)
        np.testing.assert_allclose(X.rotation().matrix(), np.eye(3), atol=1e-12)  # parallel
        faces[name] = X.translation() - [0.0, sign * inspector.GetShape(pad).size()[1] / 2, 0.0]
    return faces


# Forward kinematics of OnRobot/onrobot-ros2 onrobot_rg2.urdf, computed apart from the model
# (the fingertip frames' height from the mounting face at each opening between them), and the
# reference's pad-centre figures (shared/reference/ur3-rg2.md: 0.216 m closed, 0.215 / 0.214 /
# 0.2105 m at 20 / 30 / 45 mm, 0.182 m fully open, i.e. at the URDF's limit, 106.6 mm).
URDF_PAD_HEIGHTS = {0.0: 0.21478, 0.045: 0.21107, 0.09: 0.19475, 0.1066: 0.18092}
REFERENCE_PAD_HEIGHTS = {0.0: 0.216, 0.02: 0.215, 0.03: 0.214, 0.045: 0.2105, 0.1066: 0.182}


def test_the_linkage_opens_the_pads_and_brings_them_back_toward_the_flange(
    scene: RobotScene,
) -> None:
    """At every opening the pads' faces stand that far apart, mirrored about the centre plane,
    parallel, at the pads' height of rg2_kinematics, which is OnRobot's URDF's: the pads
    travel 16.3 mm toward the flange from the oval flanges' 45 mm to the square flange's 90 mm
    (issue 31 said about 19 mm: a straight line from 45 mm to fully open; the arc is flatter
    near closed), 33.9 mm over the URDF's stroke, 38.6 mm over the model's 110 mm."""
    heights = {}
    for opening in (0.0, 0.02, 0.03, 0.045, 0.06, 0.09, 0.1066, RG2_MAX_OPENING):
        scene.set(HOME, opening)
        left, right = _pad_faces(scene).values()
        assert left[1] - right[1] == pytest.approx(opening, abs=1e-9)
        np.testing.assert_allclose(left * [1, -1, 1], right, atol=1e-9)  # mirrored
        assert left[2] == pytest.approx(pad_height(opening), abs=1e-9)
        heights[opening] = float(left[2])
        angle = scene.plant.GetJointByName(RG2_DRIVE_JOINT).get_angle(scene.plant_context)
        assert opening_at(angle) == pytest.approx(opening, abs=1e-12)
    for opening, height in URDF_PAD_HEIGHTS.items():
        assert heights[opening] == pytest.approx(height, abs=1e-5), opening
    for opening, height in REFERENCE_PAD_HEIGHTS.items():
        assert heights[opening] == pytest.approx(height, abs=1.5e-3), opening
    assert heights[0.045] - heights[0.09] == pytest.approx(0.0163, abs=2e-4)
    assert crank_angle(0.1066) == pytest.approx(URDF_MAX_ANGLE, abs=1e-3)
    assert heights[0.0] - heights[0.1066] == pytest.approx(0.034, abs=5e-4)  # the reference's


def test_one_motor_moves_both_fingers_together_and_the_pads_along_the_approach() -> None:
    """The simulated RG2 (SAP, the station's servo on its one actuated crank), told to open to
    90 mm, then to close to 45 mm: at every step the pads stay mirrored about the centre plane
    and parallel, on the linkage's arc, the opening it measures is their gap, and where they
    settle they have travelled 16.3 mm along the approach axis."""
    device = SimulatedRg2()
    plant, context = device.plant, device.plant_context
    base = plant.GetFrameByName("rg2_base")
    fingers = [plant.GetBodyByName(name) for name in ("left_finger", "right_finger")]
    settled, t = {}, 0.0
    for target in (0.09, 0.045):
        for _ in range(60):
            t += 0.01
            opening, _, _ = device.advance(target, 20.0, t)
            left, right = (f.body_frame().CalcPose(context, base) for f in fingers)
            for X in (left, right):  # the finger frame is on its pad's face centre
                assert rotation_angle(X.rotation().matrix(), np.eye(3)) < 1e-4
            gap = left.translation()[1] - right.translation()[1]
            assert left.translation()[1] + right.translation()[1] == pytest.approx(0.0, abs=5e-5)
            assert left.translation()[2] == pytest.approx(right.translation()[2], abs=5e-5)
            assert left.translation()[2] == pytest.approx(pad_height(gap), abs=5e-5)
            assert opening == pytest.approx(gap, abs=1e-4)
        assert opening == pytest.approx(target, abs=1e-4)
        settled[target] = float(left.translation()[2])
    assert settled[0.045] - settled[0.09] == pytest.approx(0.0163, abs=2e-4)


# Contact values no other scenario uses, so that they can only come from this one.
CONTACT = (
    "{scene_graph_config: {default_proximity_properties: {static_friction: 0.7, "
    "dynamic_friction: 0.4, hydroelastic_modulus: 3.0e7}}}"
)


def test_every_collision_geometry_has_the_scenarios_friction_but_the_fingers() -> None:
    """The models state only what differs from the scenario's contact material: the RG2's
    fingers and rubber pads (1.0). The station gives every other geometry the scenario's
    friction, and SceneGraph its other contact values as defaults (seen in a context); the
    parts' bosses the scenario's modulus times BOSS_MODULUS_SCALE."""
    scenario = load_cell_scenario(None, CONTACT)
    station = make_cell_station(scenario)
    context = station.diagram.CreateDefaultContext()
    scene_graph = station.scene_graph
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    inspector = query.inspector()
    ids = inspector.GetAllGeometryIds(Role.kProximity)
    assert len(ids) >= 14
    contact = contact_material(scenario)
    fingers, others, bosses = [], [], 0
    for geometry in ids:
        props = inspector.GetProximityProperties(geometry)
        name = inspector.GetName(geometry)
        friction = props.GetProperty("material", "coulomb_friction")
        mu = (friction.static_friction(), friction.dynamic_friction())
        on_finger = name in ("rg2::finger", "rg2::pad")
        (fingers if on_finger else others).append((name, mu))
        if props.HasProperty("hydroelastic", "hydroelastic_modulus"):
            modulus = props.GetProperty("hydroelastic", "hydroelastic_modulus")
            scale = BOSS_MODULUS_SCALE if is_boss(name) else 1.0
            assert modulus == pytest.approx(contact.hydroelastic_modulus * scale), name
            bosses += is_boss(name)
    # Every boss (one under each oval flange, two under the square) presses as its 4.5 mm did:
    # the scenario's modulus scaled by its box's depth (hrc_drake.workpiece_sdf).
    assert bosses == 4
    assert len(fingers) == 4 and {mu for _, mu in fingers} == {(1.0, 1.0)}
    scenario_friction = (contact.static_friction, contact.dynamic_friction)
    wrong = sorted({(name, mu) for name, mu in others if mu != scenario_friction})
    assert wrong == [], f"not the scenario's friction {scenario_friction}: {wrong}"


def test_base_collision_clears_the_table(scene: RobotScene) -> None:
    plant, inspector = scene.plant, scene.inspector
    for link in ("base_link", "base_link_inertia"):
        body = plant.GetBodyByName(link, scene.ur3)
        for geometry in plant.GetCollisionGeometriesForBody(body):
            shape = inspector.GetShape(geometry)
            assert isinstance(shape, Cylinder)
            X_W_G = plant.CalcRelativeTransform(
                scene.plant_context, plant.world_frame(), body.body_frame()
            ) @ inspector.GetPoseInFrame(geometry)
            np.testing.assert_allclose(X_W_G.rotation().col(2), [0, 0, 1], atol=1e-12)
            assert X_W_G.translation()[2] - shape.length() / 2 >= 0.005 - 1e-12


def test_wrist_links_are_filtered_from_each_other(scene: RobotScene) -> None:
    plant, inspector = scene.plant, scene.inspector

    def geometries(link: str) -> list:
        return plant.GetCollisionGeometriesForBody(plant.GetBodyByName(link, scene.ur3))

    for a, b in [("wrist_1_link", "wrist_3_link"), ("wrist_1_link", "wrist_2_link")]:
        assert all(inspector.CollisionFiltered(g, h) for g in geometries(a) for h in geometries(b))
    assert not any(
        inspector.CollisionFiltered(g, h)
        for g in geometries("shoulder_link")
        for h in geometries("wrist_2_link")
    )


@pytest.mark.parametrize(
    "q",
    [np.zeros(6), HOME, TOOL_DOWN, np.array([0.5, -2.0, 2.2, -1.8, -1.57, 0.3])],
    ids=["zero", "home", "tool_down", "reach_over_plate"],
)
@pytest.mark.parametrize("opening", [0.0, RG2_MAX_OPENING], ids=["closed", "open"])
def test_no_self_collision_at_typical_configurations(
    scene: RobotScene, q: np.ndarray, opening: float
) -> None:
    scene.set(q, opening)
    assert scene.colliding_pairs() == []


def test_folded_elbow_does_collide(scene: RobotScene) -> None:
    # Guards the test above against filters that hide everything.
    scene.set(np.array([0.0, -math.pi / 2, 2.6, 0.0, 0.0, 0.0]))
    pairs = {frozenset(pair) for pair in scene.colliding_pairs()}
    # With the UR3's own (thin) links, the folded wrist meets the upper arm's housings.
    assert frozenset({"ur3::upper_arm_link", "ur3::wrist_2_link"}) in pairs


def test_link_shapes_follow_the_ur3_not_the_ur5(scene: RobotScene) -> None:
    """Every UR3 link's collision shapes are its real surface plus at most 5 mm."""
    plant, inspector = scene.plant, scene.inspector
    for link, surface in UR3_SURFACE_RADII.items():
        body = plant.GetBodyByName(link, scene.ur3)
        radii = [inspector.GetShape(g).radius() for g in plant.GetCollisionGeometriesForBody(body)]
        assert radii, link
        assert max(radii) <= surface + 0.005, (link, radii)
        assert max(radii) >= surface, (link, radii)
