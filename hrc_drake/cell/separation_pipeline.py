"""The separation pipeline, assembled once for the four that evaluate separation: the
controller's monitor (`hrc_drake.cell.controller.separation`), its forecast monitor
(`keep_clear_settings` in `hrc_drake.cell.controller.build`), the station's safety function
(`hrc_drake.cell.station.safety_function`) and the run's check
(`hrc_drake.cell.run.safety_check`). Each gives its own inputs and draws its own verdict; the
stages between are these, in this order:

1. the robot posed: the envelope's forward kinematics at the arm's positions and the gripper's
   opening, and its shapes (with the part or parts carried) placed in the world (`PosedRobot`);
2. the pairs: each shape's nearest point to each body sphere, and each pair's gap, the distance
   less the sphere's radius counted `1 + CHAIN_GAP` times (`BodyPairs`);
3. the speeds toward each other: the person's toward the robot along each pair's direction,
   the robot's toward the person at each shape's nearest point for rows of joint velocities;
4. the protective separation distance S_p of `hrc_drake.cell.ssm` over every pair
   (`protective_separation`), with the person's travel S_h each evaluator's own.

One `SeparationPipeline` serves each side (one envelope, so one kinematic model): the station's
for its safety function, the controller's for its monitor and its forecast monitor; the two
never share one (they may run as separate processes). It keeps what it computed, keyed on the
values it was computed from (the arm's positions, the opening, the part carried, the body
reading itself), so a question asked again costs nothing more: the forecast monitor asks about
one pose of a plan against many forecast samples, and about the same poses again for each wait
it tries. Not thread-safe, as its envelope is not.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict

import numpy as np

from hrc_drake.cell.person import CHAIN_GAP
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import (
    Pairs,
    Primitives,
    RobotEnvelope,
    nearest_to_posed,
    posed_shapes,
    speeds_toward,
)
from hrc_drake.cell.ssm import person_travel, protective_distance
from hrc_drake.scenario.safety import SafetyConfig

# Posed robots a pipeline keeps: a period's few questions; the controller's keeps the forecast
# monitor's poses of a plan's motions (a 0.1 s step over a few seconds, each asked against
# many forecast samples, again for each wait tried).
POSES_KEPT, FORECAST_POSES_KEPT = 4, 256
# Joint-velocity rows a posed robot keeps the link velocities of (the measured ones, the plan's).
VELOCITIES_KEPT = 4


class PosedRobot:
    """The envelope posed at one (q, opening) with the shapes of one part carried: the bodies'
    poses (R_WB n×3×3, p_WB n×3), the `shapes` (`Primitives`) and each shape's pose in the
    world (R_WC, p_WC), and the link velocities of the last rows of joint
    velocities asked (`links`)."""

    def __init__(self, envelope: RobotEnvelope, R_WB, p_WB, shapes: Primitives):
        self.envelope, self.R_WB, self.p_WB, self.shapes = envelope, R_WB, p_WB, shapes
        self.R_WC, self.p_WC = posed_shapes(shapes, R_WB, p_WB)
        self._links: dict[tuple, np.ndarray] = {}

    def links(self, velocities: np.ndarray) -> np.ndarray:
        """`RobotEnvelope.link_velocities` for the rows of joint `velocities` (k×6), kept."""
        velocities = np.asarray(velocities, dtype=float)
        key = (velocities.shape, velocities.tobytes())
        found = self._links.get(key)
        if found is None:
            if len(self._links) >= VELOCITIES_KEPT:
                self._links.pop(next(iter(self._links)))  # the oldest
            found = self._links[key] = self.envelope.link_velocities(
                self.R_WB, self.p_WB, velocities
            )
        return found

    def within(self, velocities: np.ndarray, body: BodySpheres, reach) -> np.ndarray:
        """Indices of the spheres of `body` that may lie nearer the robot than `reach` [m]
        (a function of the fastest any robot point moves, m/s, at joint `velocities`), by
        bounds: each shape within its bounding sphere, each shape's points no faster than its
        link's motion allows there. Cheap beside the pairs: a sensor's hundreds of voxels are
        cut to the few that can matter."""
        shapes = self.shapes
        bound = np.linalg.norm(shapes.half, axis=1) + shapes.disc + shapes.round
        link = self.links(np.asarray(velocities, dtype=float)[None, :])[0][shapes.link]
        omega, origin = link[:, 0], link[:, 1]
        centre_speed = np.linalg.norm(origin + np.cross(omega, self.p_WC), axis=1)
        fastest = float((centre_speed + np.linalg.norm(omega, axis=1) * bound).max(initial=0.0))
        gaps = body.centres[:, None, :] - self.p_WC[None, :, :]
        lower = (np.sqrt((gaps * gaps).sum(axis=2)) - bound[None, :]).min(axis=1) - body.radii
        return np.flatnonzero(lower < reach(fastest))

    def nearest(self, points: np.ndarray) -> Pairs:
        """`hrc_drake.cell.robot_envelope.nearest_points` from the shapes as posed here."""
        return nearest_to_posed(self.shapes, self.R_WC, self.p_WC, points)


class BodyPairs:
    """Every (shape, body sphere) pair of a posed robot and a body (stages 2 and 3 of the module
    docstring): `pairs` (`Pairs`), `gap` (m×n [m]), the person's speed toward the robot along
    each pair (`person_speed`) and the robot's toward the person (`robot_speeds`)."""

    def __init__(self, robot: PosedRobot, body: BodySpheres):
        self.robot, self.body = robot, body
        self.pairs = robot.nearest(body.centres)
        self.gap = self.pairs.distance - body.radii[None, :] * (1.0 + CHAIN_GAP)
        self._person: np.ndarray | None = None

    def person_speed(self) -> np.ndarray:
        """(m, n) each sphere's tracked speed toward the robot along its pair's direction [m/s]
        (signed: negative, moving away)."""
        if self._person is None:
            direction = self.pairs.direction
            self._person = -np.einsum("nj,mnj->mn", self.body.velocities, direction)
        return self._person

    def robot_speeds(self, velocities: np.ndarray) -> np.ndarray:
        """(k, m, n) the robot's speed toward each sphere at each pair's nearest point, for
        each row of joint `velocities` (k×6) [m/s] (signed: negative, moving away)."""
        return speeds_toward(self.robot.links(velocities), self.pairs)


class SeparationPipeline:
    """One side's pipeline (see the module docstring): its `envelope` and what it computed,
    kept by the values it was computed from."""

    def __init__(self, envelope: RobotEnvelope, poses_kept: int = POSES_KEPT):
        self.envelope = envelope
        self._kept = poses_kept
        self._robots: OrderedDict[tuple, PosedRobot] = OrderedDict()
        self._last: tuple[tuple, BodySpheres, BodyPairs] | None = None

    def robot(
        self,
        q: np.ndarray,
        opening: float | None,
        carrying: str | tuple[str, ...] | None,
    ) -> PosedRobot:
        """The envelope posed at arm positions `q` and the gripper's measured `opening` (None:
        the fingers over their whole travel) with the part (or parts, `RobotEnvelope.shapes`)
        `carrying`. KeyError names the parts if `carrying` is not one."""
        q = np.asarray(q, dtype=float)
        return self._posed((q.tobytes(), opening, carrying), q)

    def _posed(self, key: tuple, q: np.ndarray) -> PosedRobot:
        found = self._robots.get(key)
        if found is not None:
            self._robots.move_to_end(key)
            return found
        _, opening, carrying = key
        shapes = self.envelope.shapes(carrying, opening is not None)
        R_WB, p_WB = self.envelope.pose(q, opening)
        found = self._robots[key] = PosedRobot(self.envelope, R_WB, p_WB, shapes)
        if len(self._robots) > self._kept:
            self._robots.popitem(last=False)
        return found

    def pairs(
        self,
        q: np.ndarray,
        opening: float | None,
        carrying: str | tuple[str, ...] | None,
        body: BodySpheres,
    ) -> BodyPairs:
        """The pairs of the posed robot (`robot`) and `body`; the last asked is kept (the same
        reading asked again within a period costs nothing)."""
        q = np.asarray(q, dtype=float)
        key = (q.tobytes(), opening, carrying)
        last = self._last
        if last is not None and last[1] is body and last[0] == key:
            return last[2]
        found = BodyPairs(self._posed(key, q), body)
        self._last = (key, body, found)  # holds `body`, so its identity is not reused
        return found


_PIPELINES: weakref.WeakKeyDictionary[RobotEnvelope, SeparationPipeline] = (
    weakref.WeakKeyDictionary()
)


def pipeline_of(model: RobotEnvelope | SeparationPipeline) -> SeparationPipeline:
    """`model` itself if a pipeline, else the one pipeline of that envelope (made once)."""
    if isinstance(model, SeparationPipeline):
        return model
    found = _PIPELINES.get(model)
    if found is None:
        found = _PIPELINES[model] = SeparationPipeline(model)
    return found


def protective_separation(
    geometry: BodyPairs,
    v_r: np.ndarray,
    t_s: float,
    config: SafetyConfig,
    sampling: float = 0.0,
    travel: np.ndarray | None = None,
) -> np.ndarray:
    """S_p per pair (m×n [m], `hrc_drake.cell.ssm.protective_distance`) of the robot moving
    toward the person at `v_r` (at least 0) with stopping time `t_s`, its reaction lengthened
    by a sampling monitor's period `sampling`; the person's travel S_h is `travel` if given
    (the run's check: what they did), else as `safety.human_speed` says from their tracked
    speed over T_r + T_s + `sampling` (`hrc_drake.cell.ssm.person_travel`)."""
    if travel is None:
        window = config.reaction_time + t_s + sampling
        travel = person_travel(geometry.person_speed(), geometry.gap, window, config)
    return protective_distance(travel, v_r, t_s, config, sampling)


__all__ = [
    "FORECAST_POSES_KEPT",
    "POSES_KEPT",
    "BodyPairs",
    "PosedRobot",
    "SeparationPipeline",
    "pipeline_of",
    "protective_separation",
]
