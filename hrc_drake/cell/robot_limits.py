"""The UR's own safety limits: the speeds its safety system measures on the arm and the limit set
in force (normal or reduced). The station enforces them (its path control's cap on a command
that would break the set, and the protective stop when the measured arm breaks it all the
same); the controller plans within them (`PlanLimits`), so the cap seldom has to bind.

A UR's safety system measures the tool's speed (at the tool flange and the TCP) and the elbow's
from its joint encoders, against the limit set of its safety mode: the normal set, or the reduced
set while a configurable input or a trigger plane says so (`shared/reference/
safety-and-devices.md`). Its path control slows a motion that would break the active set; a
limit broken all the same, by more than the function's tolerance for longer than its detection
time, is a Stop Category 0 and a protective stop. The station does the same
(`hrc_drake.cell.station.safety_function`): reduced mode comes from the safety sensor's warning
field, the function's `reduced` (a person within `safety.function.reduced_band` of S_p), or the
station's `sim.safety.reduced` input.

`LimitPoints` gives the points' velocities from the joints' (a side's own robot model,
`RobotEnvelope`); the path control's target is `hrc_drake.cell.station.safety_motion.Cap`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.motion.scene import TCP
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.scenario.safety import LimitSetConfig, RobotLimitsConfig

# The UR3's tool flange frame (models/ur3/ur3.urdf: tool0 sits on the flange's face).
FLANGE = "tool0"
# Longer than any point of the arm and its tool lies from any joint axis (the UR3 reaches 0.5 m,
# the gripper and a held part add under 0.25 m): a joint speed times it bounds the speed it
# gives any point, so a slow arm needs no kinematics.
REACH = 0.8  # m


@dataclass(frozen=True)
class LimitReading:
    """The speeds a UR's safety system limits [m/s]: the tool's (the faster of the flange and
    the TCP) and the elbow's."""

    tool: float = 0.0
    elbow: float = 0.0


class LimitPoints:
    """The velocity of the tool flange, the TCP and the elbow per unit of each joint's speed,
    from `envelope`'s kinematics (the payload rides at the TCP, so the tool's points cover it)."""

    def __init__(self, envelope: RobotEnvelope):
        plant, context = envelope.plant, envelope.context
        self._envelope = envelope
        rows = {b.index(): i for i, b in enumerate(envelope.bodies)}
        self._rows = [rows[link.index()] for link in envelope.links]
        wrist = envelope.links[-1].body_frame()
        tool = (
            plant.GetFrameByName(FLANGE, plant.GetModelInstanceByName(UR3)),
            plant.GetFrameByName(TCP, plant.GetModelInstanceByName(GRIPPER)),
        )
        # Points on the last link (the flange and the TCP) and the elbow (the forearm's origin,
        # on the elbow joint's axis), each in its link's frame: (link row, point).
        self._points = [
            (len(envelope.links) - 1, plant.CalcRelativeTransform(context, wrist, f).translation())
            for f in tool
        ]
        self._points.append((2, np.zeros(3)))

    def maps(self, q: np.ndarray, opening: float | None) -> np.ndarray:
        """(3, 3, 6): the flange's, the TCP's and the elbow's velocity per joint speed at `q`."""
        R_WB, p_WB = self._envelope.pose(q, opening)
        columns = self._envelope.link_velocities(R_WB, p_WB, np.eye(len(self._rows)))
        maps = []
        for link, point in self._points:
            row = self._rows[link]
            p_W = R_WB[row] @ point + p_WB[row]
            omega, v0 = columns[:, link, 0], columns[:, link, 1]
            maps.append((v0 + np.cross(omega, p_W)).T)
        return np.array(maps)

    def reading(self, q, v, opening: float | None) -> LimitReading:
        """The speeds at joint positions `q` and speeds `v` (none computed for an arm too slow
        to move any point faster than `REACH` times its joints' speeds: a bound)."""
        bound = REACH * float(np.abs(v).sum())
        if bound == 0.0:
            return LimitReading()
        speeds = np.linalg.norm(self.maps(q, opening) @ np.asarray(v, dtype=float), axis=1)
        return LimitReading(tool=float(speeds[:2].max()), elbow=float(speeds[2]))

    def scale(self, q, v, opening: float | None, limits: LimitSetConfig) -> float:
        """The factor the joint speeds `v` at `q` may grow by (below 1: must shrink by) before
        a limit of `limits` binds; inf for an arm at rest. A bound first: a slow arm is far
        from every limit without its kinematics."""
        v = np.asarray(v, dtype=float)
        least = min(limits.tool_speed, limits.elbow_speed)
        bound = REACH * float(np.abs(v).sum())
        if bound == 0.0:
            return float("inf")
        if bound <= least:
            return least / bound  # a lower bound of the factor, and already over 1
        reading = self.reading(q, v, opening)
        return min(
            limits.tool_speed / max(reading.tool, 1e-12),
            limits.elbow_speed / max(reading.elbow, 1e-12),
        )


# The controller keeps its command this far under the limits, so that the station's cap, which
# binds at the limit itself, is not set off by round-off (our choice).
PLAN_MARGIN = 0.99


class PlanLimits:
    """The controller's reading of the limits the station enforces: the speed scale a plan may
    run at, at joint positions `q` and the plan's joint speeds `qdot` (at scale 1), under the
    set in force (`reduced`: the robot reports reduced mode); inf where nothing binds."""

    def __init__(self, envelope: RobotEnvelope, config: RobotLimitsConfig):
        self._points, self._config = LimitPoints(envelope), config

    def __call__(self, q: np.ndarray, qdot: np.ndarray, reduced: bool) -> float:
        if not self._config.enabled:
            return float("inf")
        limits = active_limits(self._config, reduced)
        return PLAN_MARGIN * self._points.scale(q, qdot, None, limits)


def active_limits(config: RobotLimitsConfig, reduced: bool) -> LimitSetConfig:
    """The limit set in force: the reduced set in reduced mode, else the normal set."""
    return config.reduced if reduced else config.normal


def exceeded(reading: LimitReading, limits: LimitSetConfig, tolerance: float) -> str | None:
    """Words naming the limit `reading` breaks by more than `tolerance` (None: none)."""
    for name, value, limit in (
        ("tool speed", reading.tool, limits.tool_speed),
        ("elbow speed", reading.elbow, limits.elbow_speed),
    ):
        if value > limit + tolerance:
            return f"{name} {value:.2f} m/s over its limit {limit:.2f} m/s"
    return None


__all__ = [
    "FLANGE",
    "PLAN_MARGIN",
    "REACH",
    "LimitPoints",
    "LimitReading",
    "PlanLimits",
    "active_limits",
    "exceeded",
]
