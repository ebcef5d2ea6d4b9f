"""The UR's own safety limits: what its safety system measures on the arm (the tool's and the
elbow's speeds, the arm's momentum) and the limit set in force (normal or reduced). The station
enforces them (its path control's cap on a command that would break the set, and the
protective stop when the measured arm breaks it all the same); the controller plans within
them (`PlanLimits`), so the cap seldom has to bind.

A UR's safety system measures the tool's speed (at the tool flange and the TCP), the elbow's
and the momentum from its joint encoders, against the limit set of its safety mode: the normal
set, or the reduced set while a configurable input or a trigger plane says so
(`shared/reference/safety-and-devices.md`). Its path control slows a motion that would break
the active set; a limit broken all the same, by more than the function's tolerance for longer
than its detection time, is a Stop Category 0 and a protective stop. The station does the same
(`hrc_drake.cell.station.safety_function`): reduced mode comes from the safety sensor's warning
field, the function's `reduced` (a person within `safety.function.reduced_band` of S_p), the
TCP past `safety.limits.reduced_plane`, or the station's `sim.safety.reduced` input.

`LimitPoints` gives the points' velocities from the joints' (a side's own robot model,
`RobotEnvelope`); the path control's target is `hrc_drake.cell.station.safety_motion.Cap`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hrc_drake.cell.robot_envelope import RobotEnvelope, cross
from hrc_drake.motion.scene import TCP
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.scenario.safety import LimitSetConfig, RobotLimitsConfig

# The UR3's tool flange frame (models/ur3/ur3.urdf: tool0 sits on the flange's face).
FLANGE = "tool0"
# Longer than any point of the arm and its tool lies from any joint axis (the UR3 reaches 0.5 m,
# the gripper and a held part add under 0.25 m): a joint speed times it bounds the speed it
# gives any point, so a slow arm needs no kinematics.
REACH = 0.8  # m
# A UR e-Series momentum limit's tolerance (its user manual's table of safety functions; a CB3's
# trueness is the same figure, `shared/reference/safety-and-devices.md` gives its detection time).
MOMENTUM_TOLERANCE = 3.0  # kg m/s


@dataclass(frozen=True)
class LimitReading:
    """What a UR's safety system limits: the tool's speed (the faster of the flange and the TCP)
    and the elbow's [m/s], and the arm's momentum [kg m/s]."""

    tool: float = 0.0
    elbow: float = 0.0
    momentum: float = 0.0


class LimitPoints:
    """The velocity of the tool flange, the TCP and the elbow, and the arm's momentum, per unit
    of each joint's speed, from `envelope`'s kinematics and masses. The payload rides at the
    TCP, so the tool's points cover its speed; its momentum is not counted (a part weighs under
    a tenth of the arm and gripper)."""

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
        masses = _link_masses(envelope)
        self.mass = float(sum(m for _, m, _ in masses))
        # Every point at once: the flange, the TCP, the elbow, then each link's centre of mass
        # (weighted by its mass, summed: the momentum), as (link rows, points in link frames).
        points = [*self._points, *((link, com) for link, _, com in masses)]
        self._links = np.array([link for link, _ in points])
        self._local = np.array([point for _, point in points])
        self._weights = np.array([m for _, m, _ in masses])
        self._kept: tuple = (None, None)  # ((q's bytes, opening), maps) `maps` last gave

    def tcp(self, q: np.ndarray, opening: float | None) -> np.ndarray:
        """The TCP's position in world at `q`."""
        R_WB, p_WB = self._envelope.pose(q, opening)
        link, point = self._points[1]
        return R_WB[self._rows[link]] @ point + p_WB[self._rows[link]]

    def maps(self, q: np.ndarray, opening: float | None) -> np.ndarray:
        """(4, 3, 6): the flange's, the TCP's and the elbow's velocity, and the arm's momentum,
        per joint speed at `q` (kept for the next call at the same `q` and `opening`)."""
        key = (np.asarray(q, dtype=float).tobytes(), opening)
        if key == self._kept[0]:
            return self._kept[1]
        R_WB, p_WB = self._envelope.pose(q, opening)
        columns = self._envelope.link_velocities(R_WB, p_WB, np.eye(len(self._rows)))
        rows = np.asarray(self._rows)[self._links]
        p_W = np.einsum("kij,kj->ki", R_WB[rows], self._local) + p_WB[rows]  # (k, 3)
        omega, v0 = columns[:, self._links, 0], columns[:, self._links, 1]  # (6, k, 3)
        velocity = v0 + cross(omega, p_W[None])  # (6, k, 3): per joint speed
        momentum = np.einsum("k,jki->ji", self._weights, velocity[:, 3:])
        maps = np.concatenate([velocity[:, :3], momentum[:, None]], axis=1).transpose(1, 2, 0)
        maps.flags.writeable = False  # kept for the next call
        self._kept = (key, maps)
        return maps

    def reading(self, q, v, opening: float | None) -> LimitReading:
        """The speeds and the momentum at joint positions `q` and speeds `v` (zero at rest)."""
        if not np.any(v):
            return LimitReading()
        values = np.linalg.norm(self.maps(q, opening) @ np.asarray(v, dtype=float), axis=1)
        return LimitReading(
            tool=float(values[:2].max()), elbow=float(values[2]), momentum=float(values[3])
        )

    def scale(self, q, v, opening: float | None, limits: LimitSetConfig) -> float:
        """The factor the joint speeds `v` at `q` may grow by (below 1: must shrink by) before
        a limit of `limits` binds; inf for an arm at rest. `v` may be rows of joint speeds (a
        plan's ahead, at `q`'s kinematics): the least factor of them. A bound first: a slow
        arm is far from every limit without its kinematics."""
        rows = np.atleast_2d(np.asarray(v, dtype=float))
        bound = REACH * float(np.abs(rows).sum(axis=1).max(initial=0.0))
        if bound == 0.0:
            return float("inf")
        least = min(limits.tool_speed, limits.elbow_speed, limits.momentum / self.mass)
        if bound <= least:
            return least / bound  # a lower bound of the factor, and already over 1
        values = np.linalg.norm(np.einsum("mij,kj->kmi", self.maps(q, opening), rows), axis=2)
        tool, elbow, momentum = values[:, :2].max(axis=1), values[:, 2], values[:, 3]
        return float(
            min(
                limits.tool_speed / max(tool.max(), 1e-12),
                limits.elbow_speed / max(elbow.max(), 1e-12),
                limits.momentum / max(momentum.max(), 1e-12),
            )
        )


# Where a limit binds, the controller keeps this far under it, so that the station's cap, which
# binds at the limit itself, is not set off by round-off (our choice).
PLAN_MARGIN = 0.999


class PlanLimits:
    """The controller's reading of the limits the station enforces: the speed scale a plan may
    run at, at joint positions `q` and the plan's joint speeds `qdot` at scale 1 (rows: now and
    ahead), under the set in force (`reduced`: the robot reports reduced mode); inf where
    nothing binds."""

    def __init__(self, envelope: RobotEnvelope, config: RobotLimitsConfig):
        self._points, self._config = LimitPoints(envelope), config

    def __call__(self, q: np.ndarray, qdot: np.ndarray, reduced: bool) -> float:
        if not self._config.enabled:
            return float("inf")
        limits = active_limits(self._config, reduced)
        scale = self._points.scale(q, qdot, None, limits)
        return scale if scale >= 1.0 else PLAN_MARGIN * scale


def beyond_plane(config: RobotLimitsConfig, tcp: np.ndarray) -> bool:
    """Whether the TCP at `tcp` lies past the reduced-mode trigger plane (none: never)."""
    plane = config.reduced_plane
    if plane is None:
        return False
    return float(np.dot(np.asarray(tcp) - plane.point, plane.normal)) > 0.0


def active_limits(config: RobotLimitsConfig, reduced: bool) -> LimitSetConfig:
    """The limit set in force: the reduced set in reduced mode, else the normal set."""
    return config.reduced if reduced else config.normal


def exceeded(reading: LimitReading, limits: LimitSetConfig, tolerance: float) -> str | None:
    """Words naming the limit `reading` breaks by more than its tolerance (None: none): the
    speeds' `tolerance` [m/s], the momentum's `MOMENTUM_TOLERANCE`."""
    for name, value, limit, slack, unit in (
        ("tool speed", reading.tool, limits.tool_speed, tolerance, "m/s"),
        ("elbow speed", reading.elbow, limits.elbow_speed, tolerance, "m/s"),
        ("momentum", reading.momentum, limits.momentum, MOMENTUM_TOLERANCE, "kg m/s"),
    ):
        if value > limit + slack:
            return f"{name} {value:.2f} {unit} over its limit {limit:.2f} {unit}"
    return None


def _link_masses(envelope: RobotEnvelope) -> list[tuple[int, float, np.ndarray]]:
    """(link row, mass [kg], centre of mass in the link's frame) of each moving arm link with
    what is welded to it (the gripper rides on the last), from the plant's default inertias and
    the gripper's default opening."""
    plant, context = envelope.plant, envelope.context
    models = (plant.GetModelInstanceByName(UR3), plant.GetModelInstanceByName(GRIPPER))
    sums: dict[int, list] = {}
    for model in models:
        for index in plant.GetBodyIndices(model):
            body = plant.get_body(index)
            link, mass = envelope.link_of(body), float(body.default_mass())
            if link == len(envelope.links) or not mass > 0:
                continue  # the fixed base, or a massless frame
            frame = envelope.links[link].body_frame()
            X_LB = plant.CalcRelativeTransform(context, frame, body.body_frame())
            moment = mass * (X_LB @ body.default_com())
            total = sums.setdefault(link, [0.0, np.zeros(3)])
            total[0] += mass
            total[1] = total[1] + moment
    return [(link, m, first / m) for link, (m, first) in sorted(sums.items())]


__all__ = [
    "FLANGE",
    "MOMENTUM_TOLERANCE",
    "PLAN_MARGIN",
    "REACH",
    "LimitPoints",
    "LimitReading",
    "PlanLimits",
    "active_limits",
    "beyond_plane",
    "exceeded",
]
