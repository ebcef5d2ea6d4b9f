"""The operator's body in the cell: a kinematic arm, torso and head beside the table.

The body is geometry in the SceneGraph (illustration and perception roles, so Meshcat and the
camera show it) with no proximity role and no place in the MultibodyPlant: it never pushes a part
and the plant never sees it. It is part of the simulated station: `OperatorBody` poses it from a
`BodyScript` of the simulated operator's activity (`hrc_drake.cell.sim_operator`) — by default
the operator of this cell, who waits with the hand at the table edge, reaches to the part while
bolting it and withdraws before the bolts are done — and publishes the body as world-frame
spheres (each capsule as a chain of spheres): what a body tracker reports, at the separation
monitor's rate.

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

from hrc_drake.cell.sim_operator import ActivityKind, OperatorActivity
from hrc_drake.hri.activity import SHOULDER, bolting_hand, min_jerk
from hrc_drake.hri.scenario import BodyConfig

UPPER_ARM, FOREARM = 0.30, 0.32  # shoulder-elbow, elbow-hand centre [m] (adult, ~50th pct)
ARM_RADII = (0.045, 0.04)
HAND_RADIUS = 0.05
TORSO_RADIUS, TORSO_LENGTH = 0.15, 0.45
HEAD_RADIUS = 0.10
TORSO_CENTRE = np.array([0.0, 0.0, 0.25])
HEAD_CENTRE = np.array([0.0, 0.0, 0.75])
CHAIN_GAP = 1 - np.sqrt(3) / 2  # of a chain sphere's radius (see `_chain`)
SKIN = Rgba(0.93, 0.75, 0.62, 1.0)
SHIRT = Rgba(0.25, 0.40, 0.65, 1.0)

# (simulated time, the simulated operator's activity, position of the part it works on or None)
#   -> the hand centre in world [m]
BodyScript = Callable[[float, OperatorActivity, np.ndarray | None], np.ndarray]


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


class BoltingScript:
    """The cell's operator: waits at the table edge; while bolting reaches to the part
    (`reach_offset` from it), bolts, and is back at rest before the bolts are done
    (`hrc_drake.hri.activity.bolting_hand`)."""

    def __init__(self, config: BodyConfig):
        self.person = config.person()
        self.left_handed = config.left_handed

    def __call__(self, now: float, activity: OperatorActivity, part: np.ndarray | None):
        """The hand centre at `now`."""
        if activity.kind != ActivityKind.BOLT or part is None:
            return np.asarray(self.person.rest_hand, dtype=float)
        return bolting_hand(self.person, now, activity.start, activity.duration, part)


class ReachInto:
    """A scripted intrusion: `delay` seconds after the operator indicated the task of decision
    step `step`, the hand moves from `rest` to `target` in `move` seconds (minimum jerk), stays
    `dwell` seconds and goes back; otherwise it rests. Times are simulated time, so the hand keeps
    its own pace whatever the robot does."""

    def __init__(
        self,
        rest,
        target,
        step: int = 1,
        delay: float = 3.0,
        move: float = 0.5,
        dwell: float = 2.0,
    ):
        self.rest, self.target = np.asarray(rest, float), np.asarray(target, float)
        self.step, self.delay = step, delay
        self.move, self.dwell = move, dwell
        self.start: float | None = None

    def __call__(self, now: float, activity: OperatorActivity, part: np.ndarray | None):
        """The hand centre at `now`."""
        if self.start is None:
            if activity.answered_step != self.step or now < activity.answered_at + self.delay:
                return self.rest
            self.start = now
        t = now - self.start
        out = min_jerk(t / self.move) - min_jerk((t - self.move - self.dwell) / self.move)
        return self.rest + out * (self.target - self.rest)


def elbow(shoulder: np.ndarray, hand: np.ndarray, left: bool = False) -> np.ndarray:
    """The elbow of a two-link arm from `shoulder` to `hand` (elbow down and outward)."""
    d_vec = hand - shoulder
    d = float(np.clip(np.linalg.norm(d_vec), 1e-6, UPPER_ARM + FOREARM - 1e-6))
    u = d_vec / max(np.linalg.norm(d_vec), 1e-9)
    a = (UPPER_ARM**2 - FOREARM**2 + d**2) / (2 * d)
    h = np.sqrt(max(UPPER_ARM**2 - a**2, 0.0))
    pole = np.array([0.0, -0.4 if left else 0.4, -1.0])
    w = pole - pole.dot(u) * u
    w /= max(np.linalg.norm(w), 1e-9)
    return shoulder + a * u + h * w


def _along(a: np.ndarray, b: np.ndarray) -> RigidTransform:
    """A pose at the middle of a→b whose z axis points along it (Drake's capsule axis)."""
    z = b - a
    return RigidTransform(RotationMatrix.MakeFromOneVector(z / np.linalg.norm(z), 2), (a + b) / 2)


def _chain_steps(radius: float, length: float) -> np.ndarray:
    """Where the spheres of a capsule of nominal `length` sit along it (0 to 1), spaced ≤ the
    radius (a fixed count per capsule): their union misses the capsule's surface by at most
    (1 − √3/2) × radius between two spheres (`CHAIN_GAP`), which the monitor subtracts."""
    return np.linspace(0.0, 1.0, int(np.ceil(1.1 * length / radius)) + 1)[:, None]


# The body's parts as sphere chains: (steps along the part, radius); computed once.
_FOREARM_STEPS = _chain_steps(ARM_RADII[1], FOREARM)
_UPPER_ARM_STEPS = _chain_steps(ARM_RADII[0], UPPER_ARM)
_TORSO_STEPS = _chain_steps(TORSO_RADIUS, TORSO_LENGTH)
_COUNTS = (1, len(_FOREARM_STEPS), len(_UPPER_ARM_STEPS), len(_TORSO_STEPS), 1)
_RADII = np.concatenate(
    [
        np.full(n, r)
        for n, r in zip(
            _COUNTS, (HAND_RADIUS, *ARM_RADII[::-1], TORSO_RADIUS, HEAD_RADIUS), strict=True
        )
    ]
)
_ENDS = np.cumsum(_COUNTS)
_GROUPS = tuple((int(e - n), int(e)) for e, n in zip(_ENDS, _COUNTS, strict=True))
_HALF_TORSO = np.array([0.0, 0.0, TORSO_LENGTH / 2])


@dataclass(frozen=True)
class BodyPose:
    """Key points of the body in world [m]."""

    def __deepcopy__(self, memo) -> BodyPose:
        return self  # immutable once made

    shoulder: np.ndarray
    elbow: np.ndarray
    hand: np.ndarray
    torso: np.ndarray
    head: np.ndarray

    def spheres(self) -> tuple[np.ndarray, np.ndarray, tuple[tuple[int, int], ...]]:
        """(centres n×3, radii n, index ranges of the parts) of the body as spheres: the hand,
        the forearm, the upper arm, the torso, the head."""
        bottom = self.torso - _HALF_TORSO
        centres = np.vstack(
            [
                self.hand,
                self.elbow + _FOREARM_STEPS * (self.hand - self.elbow),
                self.shoulder + _UPPER_ARM_STEPS * (self.elbow - self.shoulder),
                bottom + _TORSO_STEPS * (2 * _HALF_TORSO),
                self.head,
            ]
        )
        return centres, _RADII, _GROUPS


def body_pose(stance: np.ndarray, hand: np.ndarray, left: bool = False) -> BodyPose:
    """The body standing at `stance` (x, y) with the hand centre at `hand` (of the left arm
    with `left`); the torso leans toward the hand when the arm is too short."""
    base = np.array([stance[0], stance[1], 0.0])
    shoulder = base + SHOULDER * [1.0, -1.0 if left else 1.0, 1.0]
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
        elbow=elbow(shoulder, hand, left),
        hand=hand,
        torso=base + TORSO_CENTRE + lean,
        head=base + HEAD_CENTRE + lean,
    )


_EMPTY = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))


class OperatorBody(LeafSystem):
    """Poses the operator's body geometry and publishes it as spheres, every `period` seconds
    (the tracker's rate: between updates the body stands where it was last seen).

    Input ports: `activity` (OperatorActivity), `body_poses` (the plant's). Output ports:
    `geometry_pose` (FramePoseVector, to the SceneGraph source `operator`), `spheres`
    (BodySpheres)."""

    def __init__(
        self,
        scene_graph,
        plant,
        part_instances: dict[str, object],
        config: BodyConfig,
        period: float,
        script: BodyScript | None = None,
    ):
        super().__init__()
        self._stance = np.asarray(config.stance, dtype=float)
        self._script = script if script is not None else BoltingScript(config)
        self._left = bool(getattr(self._script, "left_handed", config.left_handed))
        self._part_body = {
            name: int(plant.GetBodyIndices(model)[0]) for name, model in part_instances.items()
        }
        self._period = period
        self.source_id = scene_graph.RegisterSource("operator")
        self._frames = {
            name: self._register(scene_graph, name, shape, color)
            for name, shape, color in (
                ("upper_arm", Capsule(ARM_RADII[0], UPPER_ARM), SHIRT),
                ("forearm", Capsule(ARM_RADII[1], FOREARM), SKIN),
                ("hand", Sphere(HAND_RADIUS), SKIN),
                ("torso", Capsule(TORSO_RADIUS, TORSO_LENGTH), SHIRT),
                ("head", Sphere(HEAD_RADIUS), SKIN),
            )
        }
        self._activity = self.DeclareAbstractInputPort(
            "activity", AbstractValue.Make(OperatorActivity())
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        rest = body_pose(self._stance, self._script(0.0, OperatorActivity(), None), self._left)
        self._pose = self.DeclareAbstractState(AbstractValue.Make(rest))
        self._spheres = self.DeclareAbstractState(AbstractValue.Make(_EMPTY))
        self.DeclareAbstractOutputPort(
            "geometry_pose",
            lambda: AbstractValue.Make(FramePoseVector()),
            self._calc_geometry,
            prerequisites_of_calc={self.abstract_state_ticket(self._pose)},
        )
        self.DeclareStateOutputPort("spheres", self._spheres)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def _register(self, scene_graph, name: str, shape, color: Rgba):
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
        return frame

    def pose(self, context) -> BodyPose:
        """The body's pose by its script at the context's time."""
        activity: OperatorActivity = self._activity.Eval(context)
        part = None
        if activity.part in self._part_body:
            part = self._poses.Eval(context)[self._part_body[activity.part]].translation()
        hand = np.asarray(self._script(context.get_time(), activity, part), dtype=float)
        return body_pose(self._stance, hand, self._left)

    def _update(self, context, state) -> None:
        # A tracker's velocities: the change since its last sample.
        now = self.pose(context)
        centres, radii, groups = now.spheres()
        before = context.get_abstract_state(self._spheres).get_value()
        velocities = np.zeros_like(centres)
        if len(before.centres) == len(centres):
            velocities = (centres - before.centres) / self._period
        spheres = BodySpheres(centres, radii, velocities, groups)
        state.get_mutable_abstract_state(self._pose).set_value(now)
        state.get_mutable_abstract_state(self._spheres).set_value(spheres)

    def _calc_geometry(self, context, output) -> None:
        p: BodyPose = context.get_abstract_state(self._pose).get_value()
        poses = output.get_mutable_value()
        poses.clear()
        poses.set_value(self._frames["upper_arm"], _along(p.shoulder, p.elbow))
        poses.set_value(self._frames["forearm"], _along(p.elbow, p.hand))
        poses.set_value(self._frames["hand"], RigidTransform(p.hand))
        poses.set_value(self._frames["torso"], RigidTransform(p.torso))
        poses.set_value(self._frames["head"], RigidTransform(p.head))


__all__ = [
    "BodyPose",
    "BodyScript",
    "BodySpheres",
    "BoltingScript",
    "OperatorBody",
    "ReachInto",
    "body_pose",
]
