"""The value a task's motion plan hands to the cell and the task layer."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from pydrake.trajectories import PiecewisePolynomial, Trajectory

from hrc_drake.motion.scene import Layout

# Names of the arm motions a plan is made of that other layers look up (`Plan.motions`).
LIFT = "lift"  # the part raised clear of where it was picked
HOME_LEG = "pre-place to home"  # the last motion: from above the released part, home


class Stage(StrEnum):
    """What the robot does during a segment of a task."""

    APPROACH = "approach"
    GRASP = "grasp"
    CARRY = "carry"
    PLACE = "place"
    HOLD = "hold"
    RELEASE = "release"
    RETREAT = "retreat"


@dataclass(frozen=True)
class Segment:
    """A labelled time interval [start, end] of a plan."""

    stage: Stage
    start: float
    end: float


@dataclass(frozen=True)
class CheckPhase:
    """The geometry that holds over [start, end]: which scene layout, which contacts are allowed.

    Allowed contacts are model-instance pairs: the open gripper around the part it grasps or
    releases, the carried part on its pick location or target seat / host.
    """

    start: float
    end: float
    layout: Layout
    allowed_contacts: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class MotionTiming:
    """One arm motion of a plan, over [start, start + duration].

    Attributes:
        kto_duration: KTO's own duration (free-space motions; None for straight lines).
        optimal_duration: Toppra's time-optimal duration on the same path, same limits.
        collision_constraints: KTO needed its minimum-distance constraints.
    """

    name: str
    start: float
    duration: float
    optimal_duration: float
    kto_duration: float | None = None
    collision_constraints: bool = False


@dataclass(frozen=True)
class Plan:
    """A task's motion: home → pre-grasp → grasp → carry → place, hold, release → retreat → home.

    Attributes:
        task: the task token (`F1`, `S23`, `F03`, `undo`, ...).
        instance: the part model instance moved.
        configuration: the tokens in place before the task.
        trajectory: the six UR3 joint positions over [0, duration] (joint order of the model),
            exact: a CompositeTrajectory of retimed paths and still pieces.
        gripper: opening between the finger insides [m] over [0, duration] (1×1).
        t_in_place: the part reaches its target and is held from then on.
        t_release: the gripper starts opening; the robot holds still in between.
        duration: the task's time [s].
        segments: labelled intervals covering [0, duration].
        phases: scene layout and allowed contacts over time (for validation).
        motions: timing of each arm motion.
        grip_width: the part's width between the fingers when held [m]; the gripper is
            commanded `MotionOptions.grip_squeeze` narrower, so that its fingers stall on the
            part (grip detected) and close past the width when it holds nothing.
    """

    task: str
    instance: str
    configuration: frozenset[str]
    trajectory: Trajectory
    gripper: PiecewisePolynomial
    t_in_place: float
    t_release: float
    duration: float
    segments: tuple[Segment, ...]
    phases: tuple[CheckPhase, ...]
    motions: tuple[MotionTiming, ...]
    grip_width: float = 0.0

    def positions(self, t: float) -> np.ndarray:
        """Joint positions at time t (clamped to [0, duration])."""
        return self.trajectory.value(float(np.clip(t, 0.0, self.duration))).ravel()

    def gripper_opening(self, t: float) -> float:
        """Commanded opening between the finger insides at time t [m]."""
        return float(self.gripper.value(float(np.clip(t, 0.0, self.duration)))[0, 0])

    def carrying(self, t: float) -> str | None:
        """The part instance in the gripper at time t: from the grasp's end to the release
        (None: the gripper is empty)."""
        return self.instance if self.segment(Stage.GRASP).end <= t < self.t_release else None

    def segment(self, stage: Stage) -> Segment:
        """The segment of a stage."""
        return next(s for s in self.segments if s.stage == stage)

    @property
    def motion_time(self) -> float:
        """Seconds the arm moves."""
        return sum(m.duration for m in self.motions)
