"""The shared desk in the simulated station: the operator's bins drawn on the table, and the body
script of an operator who uses them (`hrc_drake.hri.activity` is the model; the controller's
forecast of the same body is `hrc_drake.cell.controller.forecast`).

The station moves the simulated operator's body by `DeskScript` with this person's parameters
(the controller forecasts it with the population's); with `body.behaviour: unseen`, the way a
person outside the forecast's family does it (`hrc_drake.hri.unseen`), which the controller
never learns of.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    Box,
    GeometryInstance,
    IllustrationProperties,
    PerceptionProperties,
    RenderLabel,
    Rgba,
)
from pydrake.math import RigidTransform

from hrc_drake.cell.ports import ActivityKind, OperatorActivity
from hrc_drake.hri.activity import (
    Desk,
    HandTimeline,
    Person,
    bolting_hand,
    indication_timeline,
)
from hrc_drake.hri.unseen import UnseenPerson, unseen_person, unseen_timeline
from hrc_drake.layout import CellLayout
from hrc_drake.scenario.schema import Behaviour, BodyConfig

BIN_COLOUR = {"bolts": Rgba(0.55, 0.55, 0.60, 1.0), "nuts": Rgba(0.75, 0.62, 0.25, 1.0)}


def add_bins(scene_graph, layout: CellLayout) -> None:
    """Draw the layout's bins on the table (illustration and perception only: the robot's plant
    has no bins, so a layout must keep them clear of the robot's plans; `shared-desk`'s are at
    least 18 mm from the robot and what it carries in every placement plan of the flange case)."""
    if not layout.bins:
        return
    source = scene_graph.RegisterSource("desk")
    for b in layout.bins:
        length, width, height = b.size
        X = RigidTransform([b.position[0], b.position[1], height / 2])
        gid = scene_graph.RegisterAnchoredGeometry(
            source, GeometryInstance(X, Box(length, width, height), f"bin_{b.name}")
        )
        colour = BIN_COLOUR.get(b.holds, Rgba(0.5, 0.5, 0.5, 1.0))
        illustration = IllustrationProperties()
        illustration.AddProperty("phong", "diffuse", colour)
        scene_graph.AssignRole(source, gid, illustration)
        perception = PerceptionProperties()
        perception.AddProperty("phong", "diffuse", colour)
        perception.AddProperty("label", "id", RenderLabel.kDontCare)
        scene_graph.AssignRole(source, gid, perception)


class DeskScript:
    """The body script (`operator_body.BodyScript`) of an operator on a shared desk: after each
    indication the hand points, fetches and rests by `indication_timeline` (with `unseen`, by
    `unseen_timeline`: a person outside the model); it bolts the held part once its hands are
    free (`busy_until`)."""

    def __init__(self, person: Person, desk: Desk, unseen: UnseenPerson | None = None):
        self.person, self.desk, self.unseen = person, desk, unseen
        self.left_handed = person.left_handed
        self._timelines: dict[tuple, HandTimeline] = {}

    def timeline(self, activity: OperatorActivity) -> HandTimeline | None:
        """The hand's moves after the last indication (None before any)."""
        if activity.answered_step <= 0 or not activity.answered_task:
            return None
        key = (activity.answered_step, activity.answered_task, activity.answered_at)
        if key not in self._timelines:
            self._timelines = {key: self._timeline(*key)}
        return self._timelines[key]

    def _timeline(self, step: int, task: str, at: float) -> HandTimeline:
        if self.unseen is None:
            return indication_timeline(self.person, self.desk, task, at)
        return unseen_timeline(self.person, self.unseen, self.desk, task, at, step)

    def busy_until(self, activity: OperatorActivity) -> float:
        """When the hands are free to bolt: the end of the fetch of the last indication."""
        timeline = self.timeline(activity)
        return -np.inf if timeline is None else timeline.end

    def __call__(self, now: float, activity: OperatorActivity, part):
        """The hand centre at `now`."""
        if activity.kind == ActivityKind.BOLT and part is not None and now >= activity.start:
            return bolting_hand(self.person, now, activity.start, activity.duration, part)
        timeline = self.timeline(activity)
        if timeline is None:
            return np.asarray(self.person.rest_hand, dtype=float)
        return timeline.at(now)


def desk_script(body: BodyConfig, seed: int, desk: Desk) -> DeskScript:
    """The desk operator of operator `seed`: the person `body` draws for it, doing the activity
    as modelled or, with `body.behaviour: unseen`, as the unseen person of that seed does."""
    unseen = unseen_person(seed) if body.behaviour == Behaviour.UNSEEN else None
    return DeskScript(body.person(seed=seed), desk, unseen)


__all__ = [
    "DeskScript",
    "add_bins",
    "desk_script",
]
