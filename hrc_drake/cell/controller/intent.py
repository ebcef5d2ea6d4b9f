"""What the Supervisor tells its separation monitor about the motion it commands.

The monitor measures the robot (joint state) and the operator (tracked body); to say how fast the
robot may go it also needs what the robot is about to do, which only the controller knows: the
joint velocities of its plan at full speed, the part it carries (its geometry moves with the
gripper), and whether the arm is in a monitored stop (holding a part while the operator bolts).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MotionIntent:
    """The commanded motion at one control step.

    Attributes:
        qdot: the arm's joint velocities of the plan at full speed (scale 1) [rad/s]; zeros
            when the arm holds still.
        carrying: the part instance in the gripper (None: empty gripper).
        moving: the plan moves the arm now (False while holding still: a monitored stop, or
            between tasks).
        rate: the time scale the plan runs at (1: its own speed, 0: stopped).
    """

    qdot: np.ndarray = field(default_factory=lambda: np.zeros(6))
    carrying: str | None = None
    moving: bool = False
    rate: float = 1.0

    def __deepcopy__(self, memo) -> MotionIntent:
        return self  # immutable once made


__all__ = ["MotionIntent"]
