"""The motions the robot's safety system lays on the arm's servo in place of the controller's
command (`hrc_drake.cell.station.safety_function`): the brake of a stop, the blend back to the
command after one, and the cap of the UR's path control on a command that would break the
limit set in force (`hrc_drake.cell.robot_limits`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hrc_drake.cell.ssm import stopping_time
from hrc_drake.robot_names import UR3_JOINTS

_N = len(UR3_JOINTS)
# A cap lets the command go once the target has caught up with it this closely.
CAUGHT_UP = 1e-4  # rad


@dataclass(frozen=True)
class Brake:
    """A stop from joint positions `q` and velocities `v` at time `start`: every joint
    decelerates together, the fastest at `deceleration` [rad/s²], to a standstill."""

    start: float
    q: np.ndarray
    v: np.ndarray
    deceleration: float

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) of the stop at time `t`."""
        length = stopping_time(self.v, self.deceleration)
        tau = min(max(t - self.start, 0.0), length)
        if length <= 0.0:
            return self.q, np.zeros(_N)
        q = self.q + self.v * tau - self.v * tau * tau / (2.0 * length)
        return q, self.v * (1.0 - tau / length)

    def __deepcopy__(self, memo) -> Brake:
        return self  # immutable once made


@dataclass(frozen=True)
class Blend:
    """Back from the held posture `q` to the command, over `duration` s from `start`."""

    start: float
    q: np.ndarray
    duration: float

    def of(self, t: float, q_cmd: np.ndarray, v_cmd: np.ndarray):
        """(q, v) of the blend at `t` toward the command `q_cmd`, `v_cmd` (a smoothstep)."""
        x = min(max((t - self.start) / self.duration, 0.0), 1.0)
        w, rate = x * x * (3 - 2 * x), 6 * x * (1 - x) / self.duration
        return self.q + w * (q_cmd - self.q), w * v_cmd + rate * (q_cmd - self.q)

    def __deepcopy__(self, memo) -> Blend:
        return self


@dataclass(frozen=True)
class Cap:
    """The servo target the path control lays down while a command would break the active
    limits: from `q` at `start`, at joint speeds `v` (the command's, scaled down), chasing the
    command and letting it go once caught up (`chase`)."""

    start: float
    q: np.ndarray
    v: np.ndarray

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) of the target at time `t`."""
        return self.q + self.v * (t - self.start), self.v

    def __deepcopy__(self, memo) -> Cap:
        return self  # immutable once made


def chase(
    cap: Cap | None,
    q_cmd: np.ndarray,
    v_cmd: np.ndarray,
    now: float,
    period: float,
    scale,
) -> Cap | None:
    """The cap for the next `period` from `now`, toward the command (`q_cmd`, `v_cmd`), given
    `scale(v)`, the factor joint speeds `v` may grow by under the active limits
    (`LimitPoints.scale` at the arm's pose); None while the command keeps within the limits and
    the target is on it."""
    if cap is None:
        factor = scale(v_cmd)
        if factor >= 1.0:
            return None
        return Cap(now, np.array(q_cmd), np.array(v_cmd) * factor)
    q, _ = cap.at(now)
    behind = q_cmd - q
    if np.abs(behind).max(initial=0.0) <= CAUGHT_UP and scale(v_cmd) >= 1.0:
        return None
    # Toward where the command will be a period on, no faster than the limits allow.
    wanted = v_cmd + behind / period
    return Cap(now, q, wanted * min(1.0, scale(wanted)))


__all__ = ["CAUGHT_UP", "Blend", "Brake", "Cap", "chase"]
