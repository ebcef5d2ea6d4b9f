"""The UR3 arm and the RG2-like gripper: parser setup, loading, and published limits.

Limits come from ros-industrial `ur_description` `config/ur3/joint_limits.yaml` (UR3/CB3 user
manual v3.13) and OnRobot's RG2 data, as collected in the models' source comments.
"""

from __future__ import annotations

from pydrake.multibody.parsing import LoadModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.framework import Context

from hrc_drake import rg2_kinematics
from hrc_drake.resources import models_dir, package_uri

# The names (model instances, joints) live in a Drake-free module: the scenario check needs them;
# so do the UR3's joint speed limits (`robot_names.UR3_VELOCITY_LIMITS`), which the UR3
# driver's settings hold and a scenario's `drivers:` section with them.
from hrc_drake.robot_names import GRIPPER, UR3

UR3_EFFORT_LIMITS: tuple[float, ...] = (56.0, 56.0, 28.0, 12.0, 12.0, 12.0)
RG2_MAX_OPENING = rg2_kinematics.STROKE
# The RG2's gripping force range (OnRobot RG driver message definitions and product quick
# reference; shared/reference/ur3-rg2.md): the simulated gripper clips its command to it, the
# Modbus driver refuses a command outside it.
RG2_MIN_FORCE = 3.0  # N
RG2_MAX_FORCE = 40.0  # N
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
# The gripper model's linkage joints (hrc_drake.rg2_kinematics): the actuated crank first.
RG2_JOINTS: tuple[str, ...] = tuple(rg2_kinematics.JOINT_RATIOS)
RG2_DRIVE_JOINT = rg2_kinematics.DRIVE
# The left finger opens along +y of rg2_base, the right along -y (models/rg2/rg2.sdf).
RG2_OPENING_AXIS = (0.0, 1.0, 0.0)

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


def set_rg2_opening(
    plant: MultibodyPlant, context: Context | None, opening: float, gripper=None
) -> None:
    """Put the gripper's linkage at `opening` [m] between the pads: in `context` (the plant's),
    or as the plant's default positions when `context` is None. `gripper`: its model instance
    (default: the one named `rg2`)."""
    gripper = plant.GetModelInstanceByName(GRIPPER) if gripper is None else gripper
    for name, angle in rg2_kinematics.joint_angles(opening).items():
        joint = plant.GetJointByName(name, gripper)
        if context is None:
            joint.set_default_angle(angle)
        else:
            joint.set_angle(context, angle)


def rg2_opening(plant: MultibodyPlant, context: Context, gripper=None) -> float:
    """The opening between the gripper's pads [m] in `context` (the plant's), from its crank."""
    gripper = plant.GetModelInstanceByName(GRIPPER) if gripper is None else gripper
    angle = plant.GetJointByName(RG2_DRIVE_JOINT, gripper).get_angle(context)
    return rg2_kinematics.opening_at(angle)
