"""The robot's names that layers without Drake need too: the model instances of the arm and the
gripper (`models/cell/robot.dmd.yaml`) and the UR3's joints in the order of its ports, with
their speed limits. The scenario check names the joints a `!Pushed` fault may push, and the
scenario's `drivers:` section holds the UR3 driver's settings with the limits;
`hrc_drake.robot_models` (Drake) builds the robot by them."""

import math

# Model instance names of the arm and the gripper (models/cell/robot.dmd.yaml).
UR3 = "ur3"
GRIPPER = "rg2"

UR3_JOINTS: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

# The joints' speed limits [rad/s], in UR3_JOINTS order (ros-industrial `ur_description`
# config/ur3/joint_limits.yaml, UR3/CB3 user manual v3.13).
UR3_VELOCITY_LIMITS: tuple[float, ...] = (math.pi,) * 3 + (2 * math.pi,) * 3

__all__ = ["GRIPPER", "UR3", "UR3_JOINTS", "UR3_VELOCITY_LIMITS"]
