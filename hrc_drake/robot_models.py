"""The UR3 arm and the RG2-like gripper: parser setup, loading, and published limits.

Limits come from ros-industrial `ur_description` `config/ur3/joint_limits.yaml` (UR3/CB3 user
manual v3.13) and OnRobot's RG2 data, as collected in the models' source comments.
"""

from __future__ import annotations

from pydrake.multibody.parsing import LoadModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from hrc_drake.resources import models_dir, package_uri

# The names (model instances, joints) live in a Drake-free module: the scenario check needs them;
# so do the UR3's joint speed limits (`robot_names.UR3_VELOCITY_LIMITS`), which the UR3
# driver's settings hold and a scenario's `drivers:` section with them.
from hrc_drake.robot_names import GRIPPER, UR3

UR3_EFFORT_LIMITS: tuple[float, ...] = (56.0, 56.0, 28.0, 12.0, 12.0, 12.0)
RG2_MAX_OPENING = 0.110
# The RG2's gripping force range (OnRobot RG driver message definitions and product quick
# reference; shared/reference/ur3-rg2.md): the simulated gripper clips its command to it, the
# Modbus driver refuses a command outside it.
RG2_MIN_FORCE = 3.0  # N
RG2_MAX_FORCE = 40.0  # N
# Pad centre from the RG2's mounting face at a 45 mm opening (the oval flanges' width), by
# forward kinematics of OnRobot/onrobot-ros2 onrobot_rg2.urdf; our fixed tcp stands there.
RG2_PAD_CENTRE_AT_45_MM = 0.2105
# The UR3's own link surface radii (Universal_Robots_ROS2_Description, meshes/ur3/collision):
# the collision shapes are these plus a few millimetres, not the UR5 radii of ROS
# physical_parameters.yaml.
UR3_SURFACE_RADII: dict[str, float] = {
    "shoulder_link": 0.045,
    "upper_arm_link": 0.046,  # joint housings; the tube is 0.038
    "forearm_link": 0.038,  # elbow housing; the tube is 0.027
    "wrist_1_link": 0.032,
    "wrist_2_link": 0.032,
    "wrist_3_link": 0.032,
}
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
    return plant.GetModelInstanceByName(UR3), plant.GetModelInstanceByName(GRIPPER)
