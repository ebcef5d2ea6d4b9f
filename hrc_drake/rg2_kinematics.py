"""The RG2's finger linkage: one crank angle sets the opening and the pads' height.

The real RG2 drives both fingers from one motor through parallelogram linkages: each finger hangs
from a crank that swings about a pivot in the housing, and a second link keeps the fingertip
parallel to itself, so each pad moves on a circle of the crank's radius without turning. Opening
the fingers swings the pads outward *and back toward the flange*: 34 mm along the approach axis
over the stroke. This module states that geometry once; the gripper model (`models/rg2/rg2.sdf`,
whose joints and frames tests/test_robot_models.py holds to these numbers), the simulated
gripper's servo and measurement (`hrc_drake.cell.station.gripper`) and the planner's tcp rule
(`hrc_drake.motion.poses.tcp_in_part`) all ask it.

Source: OnRobot/onrobot-ros2, `onrobot_rg2/urdf/onrobot_rg2.urdf` (../shared/reference/ur3-rg2.md):
`body_joint` 0.04734 m from the mounting face along the approach axis; `finger_joint` (the
actuated crank, 0 to 1.2228 rad) 0.076 m further, 0.01695 / 0.01705 m off the centre plane; the
crank to `*_finger_base_joint` (0.054943, 0.0025 inward) m, that joint mimicking the crank with
multiplier -1 (the parallelogram); the fingertip frame (`*_finger_tip_joint`) (0.0365 along,
0.0145 inward) m from there, on the pad's face: closed, the two faces meet on the centre plane.
By forward kinematics of that file the pad face centre is 0.2148 m from the mounting face
closed, 0.2111 m at a 45 mm opening, 0.1948 m at 90 mm and 0.1809 m at the URDF's limit
(106.6 mm), which the reference's pad-centre figures (0.216, 0.2105, 0.182 m) match within
1.2 mm. OnRobot states a 110 mm stroke: the model runs the same linkage 5 degrees past the URDF's
limit to reach it (`MAX_ANGLE`, pads at 0.1762 m).

Frames: along = +z of the gripper's mounting face (the approach axis, `tool0`'s +z); out = away
from the centre plane between the fingers. Drake-free.
"""

from __future__ import annotations

import math

# The linkage, from the URDF (above), symmetric: the URDF's pivots are 0.1 mm off centre.
PIVOT_ALONG = 0.04734 + 0.076  # the crank's pivot from the mounting face [m]
PIVOT_OUT = 0.0170  # the crank's pivot from the centre plane [m]
CRANK_ALONG, CRANK_IN = 0.054943, 0.0025  # crank pivot -> finger joint, at angle 0 [m]
TIP_ALONG, TIP_IN = 0.0365, 0.0145  # finger joint -> the pad face centre [m]
CRANK = math.hypot(CRANK_ALONG, CRANK_IN)  # the crank's length: the pads' circle [m]
CRANK_TILT = math.atan2(CRANK_IN, CRANK_ALONG)  # the crank leans inward this much at angle 0
URDF_MAX_ANGLE = 1.22277767395  # the URDF's finger_joint limit [rad]

STROKE = 0.110  # m between the pads, OnRobot's figure (robot_models.RG2_MAX_OPENING)
# The opening at which the model's fixed `tcp` frame is the pads' centre: the oval flanges'
# width, most of the cell's grasps.
TCP_OPENING = 0.045  # m

# The model's joints: the actuated crank, and the five the linkage makes follow it, each
# q = ratio * q(DRIVE) (Drake coupler constraints, `drake:mimic` in the model). The arms are
# the real linkage's, about PIVOT; each finger hangs from a crank of the same length and angle
# about the centre of its pad's circle (PIVOT moved by the TIP offset), at its pad face centre,
# so that the pad's squeeze does not twist the finger against its coupler; the finger joint
# turns back by as much as the crank turns, so the finger stays parallel.
DRIVE = "left_crank_joint"
JOINT_RATIOS: dict[str, float] = {
    "left_crank_joint": 1.0,
    "right_crank_joint": 1.0,
    "left_arm_joint": 1.0,
    "right_arm_joint": 1.0,
    "left_finger_joint": -1.0,
    "right_finger_joint": -1.0,
}


def _check_opening(opening: float) -> float:
    opening = float(opening)
    if not -1e-9 <= opening <= STROKE + 1e-9:
        raise ValueError(
            f"an RG2 opening of {opening} m is outside its stroke, 0 to {STROKE} m; clip the "
            "command to the stroke"
        )
    return min(max(opening, 0.0), STROKE)


def opening_at(angle: float) -> float:
    """The opening between the pads [m] at crank `angle` [rad] (0: closed)."""
    return 2.0 * (PIVOT_OUT - TIP_IN + CRANK * math.sin(angle - CRANK_TILT))


def crank_angle(opening: float) -> float:
    """The crank angle [rad] that opens the pads `opening` [m] apart (0 to STROKE)."""
    half = 0.5 * _check_opening(opening)
    sine = (half - (PIVOT_OUT - TIP_IN)) / CRANK
    return math.asin(min(1.0, sine)) + CRANK_TILT


def opening_rate(angle: float) -> float:
    """d(opening)/d(angle) [m/rad] at crank `angle`: the lever from the motor to the pads (a
    torque tau on the crank squeezes a part with tau / opening_rate on each pad)."""
    return 2.0 * CRANK * math.cos(angle - CRANK_TILT)


def pad_height(opening: float) -> float:
    """How far the pads' centre stands from the mounting face along the approach axis [m] with
    the fingers `opening` apart."""
    angle = crank_angle(opening)
    return PIVOT_ALONG + TIP_ALONG + CRANK * math.cos(angle - CRANK_TILT)


def pad_offset(opening: float) -> float:
    """How far the pads' centre stands along the approach axis from the model's fixed `tcp`
    frame at `opening` [m]: 0 at TCP_OPENING, negative (toward the flange) wider."""
    return pad_height(opening) - pad_height(TCP_OPENING)


def pad_travel_rate(opening: float) -> float:
    """d(pad_height)/d(opening) at `opening` [m/m]: negative, the pads come back toward the
    flange as they open (-0.19 at 45 mm, -0.61 at 90 mm). So a load that pulls the pads away from
    the flange, such as the weight W of a part they hold from above, squeezes it harder: the
    servo's force F on each pad becomes F + W * |rate| (the linkage's virtual work)."""
    angle = crank_angle(opening)
    return -CRANK * math.sin(angle - CRANK_TILT) / opening_rate(angle)


def joint_angles(opening: float) -> dict[str, float]:
    """The model's joint positions [rad] (joint name -> angle) at `opening` [m]."""
    angle = crank_angle(opening)
    return {name: ratio * angle for name, ratio in JOINT_RATIOS.items()}


MAX_ANGLE = crank_angle(STROKE)
TCP_HEIGHT = pad_height(TCP_OPENING)  # the model's `tcp` frame from the mounting face [m]

__all__ = [
    "CRANK",
    "CRANK_TILT",
    "DRIVE",
    "JOINT_RATIOS",
    "MAX_ANGLE",
    "STROKE",
    "TCP_HEIGHT",
    "TCP_OPENING",
    "URDF_MAX_ANGLE",
    "crank_angle",
    "joint_angles",
    "opening_at",
    "opening_rate",
    "pad_height",
    "pad_offset",
    "pad_travel_rate",
]
