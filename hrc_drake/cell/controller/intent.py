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
        ahead: the plan's joint velocities at full speed from now until a limit the monitor
            sets now governs the arm (`SupervisorLimits.look_ahead`; `plan_velocities`; rows,
            `qdot` first; None: `qdot` alone): a plan that speeds up meanwhile moves faster
            than `qdot` says.
    """

    qdot: np.ndarray = field(default_factory=lambda: np.zeros(6))
    carrying: str | None = None
    moving: bool = False
    rate: float = 1.0
    ahead: np.ndarray | None = None

    def velocities_ahead(self) -> np.ndarray:
        """`ahead`, or `qdot` as its one row."""
        return np.atleast_2d(self.qdot if self.ahead is None else self.ahead)

    def __deepcopy__(self, memo) -> MotionIntent:
        return self  # immutable once made


# Samples of the plan's velocity over the look-ahead window (its ends included).
AHEAD_SAMPLES = 4


def plan_velocities(trajectory, tau: float, duration: float, window: float) -> np.ndarray:
    """(AHEAD_SAMPLES × joints) the `trajectory`'s velocities at full speed at plan times from
    `tau` to `tau + window`, none past `duration` (the plan time runs no faster than this at
    any speed scale)."""
    times = np.minimum(np.linspace(tau, tau + window, AHEAD_SAMPLES), duration)
    return np.stack([trajectory.EvalDerivative(float(t), 1).ravel() for t in times])


__all__ = ["AHEAD_SAMPLES", "MotionIntent", "plan_velocities"]
