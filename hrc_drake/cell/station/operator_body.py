"""The operator's body in the cell: a kinematic arm, torso and head beside the table.

The body is geometry in the SceneGraph (illustration and perception roles, so Meshcat and the
camera show it) with no proximity role and no place in the MultibodyPlant: it never pushes a part
and the plant never sees it. It is part of the simulated station: `OperatorBody` poses it from a
`BodyScript` of the simulated operator's activity (`hrc_drake.cell.station.sim_operator`) — by
default the operator of this cell, who waits with the hand at the table edge, reaches to the part
while bolting it and withdraws before the bolts are done — and publishes the body as world-frame
spheres (each capsule as a chain of spheres): what a body tracker reports, at the separation
monitor's rate.

The arm is two capsules (upper arm, forearm) and a hand sphere; the elbow comes from the shoulder
and the hand by two-link inverse kinematics, and the torso leans in when the hand reaches further
than the arm is long.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

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

from hrc_drake.cell.person import (
    ARM_RADII,
    FOREARM,
    HAND_RADIUS,
    HEAD_RADIUS,
    TORSO_LENGTH,
    TORSO_RADIUS,
    UPPER_ARM,
    BodyPose,
    body_pose,
)
from hrc_drake.cell.ports import NOBODY, ActivityKind, BodySpheres, OperatorActivity
from hrc_drake.hri.activity import bolting_hand, min_jerk
from hrc_drake.scenario.schema import BodyConfig

SKIN = Rgba(0.93, 0.75, 0.62, 1.0)
SHIRT = Rgba(0.25, 0.40, 0.65, 1.0)
_PARTS = ("upper_arm", "forearm", "hand", "torso", "head")  # the order _calc_geometry poses them

# (simulated time, the simulated operator's activity, position of the part it works on or None)
#   -> the hand centre in world [m]
BodyScript = Callable[[float, OperatorActivity, np.ndarray | None], np.ndarray]


@runtime_checkable
class KnowsWhenFree(Protocol):
    """A body script whose hands may be busy elsewhere (at the desk's bins): the simulated
    operator starts bolting once they are free."""

    def busy_until(self, activity: OperatorActivity) -> float:
        """When the hands are free for the activity's part [s, simulated]."""


@runtime_checkable
class Handed(Protocol):
    """A body script that says which hand it moves (else the body config's)."""

    left_handed: bool


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


def _along(a: np.ndarray, b: np.ndarray) -> RigidTransform:
    """A pose at the middle of a→b whose z axis points along it (Drake's capsule axis)."""
    z = b - a
    return RigidTransform(RotationMatrix.MakeFromOneVector(z / np.linalg.norm(z), 2), (a + b) / 2)


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
        script = self._script
        self._left = bool(script.left_handed if isinstance(script, Handed) else config.left_handed)
        self._part_body = {
            name: int(plant.GetBodyIndices(model)[0]) for name, model in part_instances.items()
        }
        self._period = period
        # The body at the last hand position posed, by the hand's bytes, and the frames of the
        # last pose drawn (the hand stands still for much of a run: the same pose, exactly).
        self._posed: tuple[tuple, BodyPose | None, tuple] = ((), None, ())
        self._drawn: tuple[BodyPose | None, tuple[RigidTransform, ...]] = (None, ())
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
        self._spheres = self.DeclareAbstractState(AbstractValue.Make(NOBODY))
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
        return self._posed_at(context)[0]

    def _posed_at(self, context) -> tuple[BodyPose, tuple]:
        """The body's pose by its script at the context's time, and its spheres."""
        activity: OperatorActivity = self._activity.Eval(context)
        part = None
        if activity.part in self._part_body:
            part = self._poses.Eval(context)[self._part_body[activity.part]].translation()
        hand = np.asarray(self._script(context.get_time(), activity, part), dtype=float)
        key = hand.shape, hand.tobytes()
        if key != self._posed[0]:
            posed = body_pose(self._stance, hand, self._left)
            self._posed = (key, posed, posed.spheres())
        return self._posed[1], self._posed[2]

    def _update(self, context, state) -> None:
        # A tracker's velocities: the change since its last sample.
        now, (centres, radii, groups) = self._posed_at(context)
        before = context.get_abstract_state(self._spheres).get_value()
        velocities = np.zeros_like(centres)
        if len(before.centres) == len(centres):
            velocities = (centres - before.centres) / self._period
        spheres = BodySpheres(centres, radii, velocities, groups)
        state.get_mutable_abstract_state(self._pose).set_value(now)
        state.get_mutable_abstract_state(self._spheres).set_value(spheres)

    def _calc_geometry(self, context, output) -> None:
        p: BodyPose = context.get_abstract_state(self._pose).get_value()
        if p is not self._drawn[0]:
            frames = (
                _along(p.shoulder, p.elbow),
                _along(p.elbow, p.hand),
                RigidTransform(p.hand),
                RigidTransform(p.torso),
                RigidTransform(p.head),
            )
            self._drawn = (p, frames)
        poses = output.get_mutable_value()
        poses.clear()
        for name, X in zip(_PARTS, self._drawn[1], strict=True):
            poses.set_value(self._frames[name], X)


__all__ = [
    "BodyPose",
    "BodyScript",
    "BodySpheres",
    "BoltingScript",
    "Handed",
    "KnowsWhenFree",
    "OperatorBody",
    "ReachInto",
    "body_pose",
]
