"""The operator's body in the cell: a kinematic arm, torso and head beside the table.

The body is geometry in the SceneGraph (illustration and perception roles, so Meshcat and the
camera show it) with no proximity role and no place in the MultibodyPlant: it never pushes a part
and the plant never sees it. `OperatorBody` poses it from a `BodyScript` — by default the
operator of this cell, who waits with the hand at the table edge, reaches to the part while the
robot holds it, bolts and withdraws before the release — and publishes the body as world-frame
spheres (each capsule as a chain of spheres) for the separation monitor (`hrc_drake.cell.safety`).

The arm is two capsules (upper arm, forearm) and a hand sphere; the elbow comes from the shoulder
and the hand by two-link inverse kinematics, and the torso leans in when the hand reaches further
than the arm is long.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    Capsule,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    IllustrationProperties,
    PerceptionProperties,
    RenderLabel,
    Rgba,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem

from hrc_drake.cell.supervisor import Mode, SupervisorStatus
from hrc_drake.hri.scenario import BodyConfig
from hrc_drake.motion.plan import Stage

UPPER_ARM, FOREARM = 0.30, 0.32  # shoulder-elbow, elbow-hand centre [m] (adult, ~50th pct)
ARM_RADII = (0.045, 0.04)
HAND_RADIUS = 0.05
TORSO_RADIUS, TORSO_LENGTH = 0.15, 0.45
HEAD_RADIUS = 0.10
SHOULDER = np.array([-0.05, 0.18, 0.50])  # right shoulder from the stance point at table height
TORSO_CENTRE = np.array([0.0, 0.0, 0.25])
HEAD_CENTRE = np.array([0.0, 0.0, 0.75])
CHAIN_GAP = 1 - np.sqrt(3) / 2  # of a chain sphere's radius (see `_chain`)
SKIN = Rgba(0.93, 0.75, 0.62, 1.0)
SHIRT = Rgba(0.25, 0.40, 0.65, 1.0)

# (simulated time, Supervisor status, position of the part the robot handles or None)
#   -> the hand centre in world [m]
BodyScript = Callable[[float, SupervisorStatus, np.ndarray | None], np.ndarray]


@dataclass(frozen=True)
class BodySpheres:
    """The body as world-frame spheres: centres (n×3) [m], radii (n) [m], velocities (n×3)
    [m/s]; `groups` are the index ranges [start, end) of the body's parts (hand, forearm, upper
    arm, torso, head), each part within the sphere `bound(group)`."""

    centres: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray
    groups: tuple[tuple[int, int], ...] = ()

    def bound(self, group: int) -> tuple[np.ndarray, float]:
        """(centre, radius) of a sphere that holds every sphere of `group`."""
        start, end = self.groups[group]
        a, b = self.centres[start], self.centres[end - 1]
        centre = (a + b) / 2
        return centre, float(np.linalg.norm(b - a) / 2 + self.radii[start:end].max())

    def __deepcopy__(self, memo) -> BodySpheres:
        return self  # immutable once made (Drake copies abstract values often)


def min_jerk(x: float) -> float:
    """The minimum-jerk profile 10x³ − 15x⁴ + 6x⁵ on [0, 1] (peak slope 1.875)."""
    x = float(np.clip(x, 0.0, 1.0))
    return x**3 * (10 - 15 * x + 6 * x**2)


class BoltingScript:
    """The cell's operator: waits at the table edge; during the plan's hold reaches to the held
    part (`reach_offset` from it), bolts, and is back at rest before the release.

    Reach and withdrawal take `reach_time` each, shortened to fit three of them in the hold; a
    reach the hand cannot make within `hand_speed` in that time (a minimum-jerk motion peaks at
    1.875 × distance / time) stops short along the way (lean runs' 0.5 s holds)."""

    def __init__(self, config: BodyConfig):
        self.rest = np.asarray(config.rest_hand, dtype=float)
        self.offset = np.asarray(config.reach_offset, dtype=float)
        self.speed, self.reach_time = config.hand_speed, config.reach_time

    def __call__(self, now: float, status: SupervisorStatus, part: np.ndarray | None):
        """The hand centre at `now`."""
        plan = status.plan
        if status.mode != Mode.EXECUTE or plan is None or part is None:
            return self.rest
        hold = next((g for g in plan.segments if g.stage == Stage.HOLD), None)
        if hold is None:
            return self.rest
        length = hold.end - hold.start
        phase = status.plan_time(now) - hold.start
        if length <= 0 or not 0.0 <= phase <= length:
            return self.rest
        move = min(self.reach_time, length / 3)
        path = part + self.offset - self.rest
        reach = min(1.0, self.speed * move / 1.875 / max(np.linalg.norm(path), 1e-9))
        out = min_jerk(phase / move) - min_jerk((phase - (length - 1.25 * move)) / move)
        return self.rest + reach * out * path


class ReachInto:
    """A scripted intrusion: at decision step `step`, once the plan's time passes the start of
    `stage` plus `delay`, the hand moves from `rest` to `target` in `move` seconds (minimum
    jerk), stays `dwell` seconds and goes back; otherwise it rests. Times after the trigger are
    simulated time, so the hand keeps its own pace whatever the robot does."""

    def __init__(
        self,
        rest,
        target,
        step: int = 1,
        stage: Stage = Stage.CARRY,
        delay: float = 0.2,
        move: float = 0.5,
        dwell: float = 2.0,
    ):
        self.rest, self.target = np.asarray(rest, float), np.asarray(target, float)
        self.step, self.stage, self.delay = step, stage, delay
        self.move, self.dwell = move, dwell
        self.start: float | None = None

    def __call__(self, now: float, status: SupervisorStatus, part: np.ndarray | None):
        """The hand centre at `now`."""
        if self.start is None:
            plan = status.plan
            if status.mode != Mode.EXECUTE or plan is None or status.step != self.step:
                return self.rest
            trigger = plan.segment(self.stage).start + self.delay
            if status.plan_time(now) < trigger:
                return self.rest
            self.start = now
        t = now - self.start
        out = min_jerk(t / self.move) - min_jerk((t - self.move - self.dwell) / self.move)
        return self.rest + out * (self.target - self.rest)


def elbow(shoulder: np.ndarray, hand: np.ndarray) -> np.ndarray:
    """The elbow of a two-link arm from `shoulder` to `hand` (elbow down and outward)."""
    d_vec = hand - shoulder
    d = float(np.clip(np.linalg.norm(d_vec), 1e-6, UPPER_ARM + FOREARM - 1e-6))
    u = d_vec / max(np.linalg.norm(d_vec), 1e-9)
    a = (UPPER_ARM**2 - FOREARM**2 + d**2) / (2 * d)
    h = np.sqrt(max(UPPER_ARM**2 - a**2, 0.0))
    pole = np.array([0.0, 0.4, -1.0])
    w = pole - pole.dot(u) * u
    w /= max(np.linalg.norm(w), 1e-9)
    return shoulder + a * u + h * w


def _along(a: np.ndarray, b: np.ndarray) -> RigidTransform:
    """A pose at the middle of a→b whose z axis points along it (Drake's capsule axis)."""
    z = b - a
    return RigidTransform(RotationMatrix.MakeFromOneVector(z / np.linalg.norm(z), 2), (a + b) / 2)


def _chain(a: np.ndarray, b: np.ndarray, radius: float, length: float) -> np.ndarray:
    """Centres of spheres along the capsule a–b of nominal `length`, spaced ≤ the radius (a
    fixed count per capsule): their union misses the capsule's surface by at most
    (1 − √3/2) × radius between two spheres (`CHAIN_GAP`), which the monitor subtracts."""
    n = int(np.ceil(1.1 * length / radius)) + 1
    return np.linspace(a, b, n)


@dataclass(frozen=True)
class BodyPose:
    """Key points of the body in world [m]."""

    shoulder: np.ndarray
    elbow: np.ndarray
    hand: np.ndarray
    torso: np.ndarray
    head: np.ndarray

    def spheres(self) -> tuple[np.ndarray, np.ndarray, tuple[tuple[int, int], ...]]:
        """(centres n×3, radii n, index ranges of the parts) of the body as spheres."""
        half = np.array([0, 0, TORSO_LENGTH / 2])
        parts = [
            (self.hand[None, :], HAND_RADIUS),
            (_chain(self.elbow, self.hand, ARM_RADII[1], FOREARM), ARM_RADII[1]),
            (_chain(self.shoulder, self.elbow, ARM_RADII[0], UPPER_ARM), ARM_RADII[0]),
            (
                _chain(self.torso - half, self.torso + half, TORSO_RADIUS, TORSO_LENGTH),
                TORSO_RADIUS,
            ),
            (self.head[None, :], HEAD_RADIUS),
        ]
        centres = np.vstack([c for c, _ in parts])
        radii = np.concatenate([np.full(len(c), r) for c, r in parts])
        ends = np.cumsum([len(c) for c, _ in parts])
        groups = tuple((int(e - len(c)), int(e)) for e, (c, _) in zip(ends, parts, strict=True))
        return centres, radii, groups


def body_pose(stance: np.ndarray, hand: np.ndarray) -> BodyPose:
    """The body standing at `stance` (x, y) with the hand centre at `hand`; the torso leans
    toward the hand when the arm is too short."""
    base = np.array([stance[0], stance[1], 0.0])
    shoulder = base + SHOULDER
    reach = np.linalg.norm(hand - shoulder)
    limit = 0.97 * (UPPER_ARM + FOREARM)
    lean = np.zeros(3)
    if reach > limit:
        # Lean horizontally toward the hand until the arm reaches it.
        d = hand - shoulder
        horizontal = float(np.hypot(d[0], d[1]))
        needed = np.sqrt(max(limit**2 - min(d[2] ** 2, limit**2), 0.0))
        lean[:2] = d[:2] / max(horizontal, 1e-9) * max(horizontal - needed, 0.0)
    shoulder = shoulder + lean
    return BodyPose(
        shoulder=shoulder,
        elbow=elbow(shoulder, hand),
        hand=hand,
        torso=base + TORSO_CENTRE + lean,
        head=base + HEAD_CENTRE + lean,
    )


class OperatorBody(LeafSystem):
    """Poses the operator's body geometry and publishes it as spheres.

    Input ports: `status` (SupervisorStatus), `body_poses` (the plant's). Output ports:
    `geometry_pose` (FramePoseVector, to the SceneGraph source `operator`), `spheres`
    (BodySpheres)."""

    def __init__(
        self,
        scene_graph,
        plant,
        part_instances: dict[str, object],
        config: BodyConfig,
        script: BodyScript | None = None,
    ):
        super().__init__()
        self._stance = np.asarray(config.stance, dtype=float)
        self._script = script if script is not None else BoltingScript(config)
        self._part_body = {
            name: int(plant.GetBodyIndices(model)[0]) for name, model in part_instances.items()
        }
        self.source_id = scene_graph.RegisterSource("operator")
        self._frames = {}
        for name, shape, color in (
            ("upper_arm", Capsule(ARM_RADII[0], UPPER_ARM), SHIRT),
            ("forearm", Capsule(ARM_RADII[1], FOREARM), SKIN),
            ("hand", Sphere(HAND_RADIUS), SKIN),
            ("torso", Capsule(TORSO_RADIUS, TORSO_LENGTH), SHIRT),
            ("head", Sphere(HEAD_RADIUS), SKIN),
        ):
            frame = scene_graph.RegisterFrame(self.source_id, GeometryFrame(f"operator_{name}"))
            gid = scene_graph.RegisterGeometry(
                self.source_id, frame, GeometryInstance(RigidTransform(), shape, name)
            )
            illustration = IllustrationProperties()
            illustration.AddProperty("phong", "diffuse", color)
            scene_graph.AssignRole(self.source_id, gid, illustration)
            perception = PerceptionProperties()
            perception.AddProperty("phong", "diffuse", color)
            perception.AddProperty("label", "id", RenderLabel.kDontCare)
            scene_graph.AssignRole(self.source_id, gid, perception)
            self._frames[name] = frame
        self._status_port = self.DeclareAbstractInputPort(
            "status", AbstractValue.Make(SupervisorStatus())
        )
        self._poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self.DeclareAbstractOutputPort(
            "geometry_pose", lambda: AbstractValue.Make(FramePoseVector()), self._calc_geometry
        )
        empty = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
        self.DeclareAbstractOutputPort(
            "spheres", lambda: AbstractValue.Make(empty), self._calc_spheres
        )

    def pose(self, context, dt: float = 0.0) -> BodyPose:
        """The body's pose at the context's time minus `dt`."""
        status: SupervisorStatus = self._status_port.Eval(context)
        part = None
        if status.pending is not None and status.pending[2] in self._part_body:
            poses = self._poses_port.Eval(context)
            part = poses[self._part_body[status.pending[2]]].translation()
        hand = np.asarray(self._script(context.get_time() - dt, status, part), dtype=float)
        return body_pose(self._stance, hand)

    def _calc_geometry(self, context, output) -> None:
        p = self.pose(context)
        poses = output.get_mutable_value()
        poses.clear()
        poses.set_value(self._frames["upper_arm"], _along(p.shoulder, p.elbow))
        poses.set_value(self._frames["forearm"], _along(p.elbow, p.hand))
        poses.set_value(self._frames["hand"], RigidTransform(p.hand))
        poses.set_value(self._frames["torso"], RigidTransform(p.torso))
        poses.set_value(self._frames["head"], RigidTransform(p.head))

    def _calc_spheres(self, context, output) -> None:
        dt = 2e-3
        centres, radii, groups = self.pose(context).spheres()
        before, _, _ = self.pose(context, dt).spheres()
        output.set_value(BodySpheres(centres, radii, (centres - before) / dt, groups))


__all__ = [
    "BodyPose",
    "BodyScript",
    "BodySpheres",
    "BoltingScript",
    "OperatorBody",
    "ReachInto",
    "body_pose",
]
