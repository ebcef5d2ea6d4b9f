"""The robot's names that layers without Drake need too: the model instances of the arm and the
gripper (`models/cell/robot.dmd.yaml`) and the UR3's joints in the order of its ports. The
scenario check names the joints a `!Pushed` fault may push; `hrc_drake.robot_models` (Drake)
builds the robot by them."""

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

__all__ = ["GRIPPER", "UR3", "UR3_JOINTS"]
