"""Limits and tuning of the motion layer, in one frozen value."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MotionOptions:
    """Limits, offsets and solver settings for planning one task.

    Joint position and velocity limits come from the UR3 model; the UR3's acceleration limit is
    not published (ros-industrial ur_description joint_limits.yaml gives none), so
    `joint_acceleration_limit` is our choice.
    """

    joint_acceleration_limit: float = 5.0
    """rad/s² on every joint; not published by Universal Robots, 5 is what calibration used."""
    tcp_speed_limit: float = 0.25
    """m/s; ISO 10218-1 reduced speed for collaborative operation."""
    limit_fraction: float = 0.98
    """Retime below the limits so that a plan sampled between Toppra's grid points still passes."""
    clearance: float = 0.005
    """m; the minimum distance a valid plan keeps (validation threshold)."""
    clearance_margin: float = 0.007
    """m; added to `clearance` in the optimisers, since constraints hold only at samples."""
    approach_distance: float = 0.06
    """m; pre-grasp / pre-place / retreat offset along the tool's approach axis."""
    finger_gap: float = 0.008
    """m; each finger's gap to the part when open around it (the RG2 opens to any width)."""
    grip_squeeze: float = 0.002
    """m the gripper is commanded past a part's width: its fingers stall on the part (a real RG2
    then reports a grip), and close past the width when there is none."""
    straight_steps: int = 6
    """IK waypoints along a straight approach or retreat."""
    kto_control_points: int = 10
    collision_samples: int = 60
    """Minimum-distance constraints along a free KTO path (dense: 25 left 2 mm dips)."""
    check_samples: int = 150
    """Samples to check a KTO path's clearance before and after adding collision constraints."""
    gripper_time: float = 0.5
    """s to open or close the gripper."""
    hold_time: float = 5.0
    """s the robot holds a placed part still while the operator bolts it."""
    undo_hold_time: float = 0.0
    """s the robot waits after putting a part back in the tray (nothing to bolt)."""
    validation_rate: float = 100.0
    """Hz at which plans are sampled for validation."""
    seed: int = 0
    """Seed of the random IK seeds; same seed, same plans."""
