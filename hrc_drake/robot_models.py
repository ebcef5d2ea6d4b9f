"""The UR3 arm and the RG2-like gripper: parser setup, loading, and published limits.

Limits come from ros-industrial `ur_description` `config/ur3/joint_limits.yaml` (UR3/CB3 user
manual v3.13) and OnRobot's RG2 data, as collected in the models' source comments.
"""

from __future__ import annotations

import math

from pydrake.multibody.parsing import LoadModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from hrc_drake.resources import models_dir, package_uri

UR3_JOINTS: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
UR3_VELOCITY_LIMITS: tuple[float, ...] = (math.pi,) * 3 + (2 * math.pi,) * 3
UR3_EFFORT_LIMITS: tuple[float, ...] = (56.0, 56.0, 28.0, 12.0, 12.0, 12.0)
RG2_MAX_OPENING = 0.110
RG2_FINGER_JOINTS: tuple[str, ...] = ("left_finger_joint", "right_finger_joint")

ROBOT_DIRECTIVES = "cell/robot.dmd.yaml"


def make_parser(plant: MultibodyPlant) -> Parser:
    """A Parser for `plant` whose package map resolves `package://hrc_drake_models/...`."""
    parser = Parser(plant)
    parser.package_map().AddPackageXml(str(models_dir() / "package.xml"))
    return parser


def add_robot(plant: MultibodyPlant) -> tuple[ModelInstanceIndex, ModelInstanceIndex]:
    """Add the UR3 (welded to world at the origin) and the gripper (welded to `tool0`).

    Uses `models/cell/robot.dmd.yaml`; returns the model instances `(ur3, rg2)`.
    """
    parser = make_parser(plant)
    directives_path = parser.package_map().ResolveUrl(package_uri(ROBOT_DIRECTIVES))
    directives = LoadModelDirectives(directives_path)
    ProcessModelDirectives(directives, plant, parser)
    return plant.GetModelInstanceByName("ur3"), plant.GetModelInstanceByName("rg2")
