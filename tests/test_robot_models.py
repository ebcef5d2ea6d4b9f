"""The UR3 and RG2 models against the published figures (see the models' source comments)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.multibody.plant import MultibodyPlant

from hrc_drake.resources import package_uri
from hrc_drake.robot_models import (
    UR3_EFFORT_LIMITS,
    UR3_JOINTS,
    UR3_VELOCITY_LIMITS,
    add_robot,
    make_parser,
)

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
