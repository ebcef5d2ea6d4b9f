"""A plan's timeline: its arm motions and still intervals chained into one exact trajectory, with
the bookkeeping of time that goes with them (the stages, the contact-check phases, each motion's
timing and the gripper's openings).

Apart from the planner because it is about when, not where: the planner finds the paths; this
lays them end to end as `plan_io` later writes them out piece by piece.
"""

from __future__ import annotations

import numpy as np
from pydrake.trajectories import CompositeTrajectory, PiecewisePolynomial, Trajectory

from hrc_drake.motion.plan import CheckPhase, MotionTiming, Segment, Stage
from hrc_drake.motion.scene import Layout
from hrc_drake.motion.trajectory import Retimed


class Timeline:
    """Chains arm motions and still intervals into one exact trajectory (no resampling): each
    retimed move is a `PathParameterizedTrajectory`, each still interval a constant piece, and
    the plan a `CompositeTrajectory` of them."""

    def __init__(self, q0: np.ndarray, opening: float):
        self.t = 0.0
        self.q_end = np.asarray(q0, dtype=float)
        self.pieces: list[Trajectory] = []
        self.segments: list[Segment] = []
        self.phases: list[CheckPhase] = []
        self.motions: list[MotionTiming] = []
        self.gripper_times = [0.0]
        self.gripper_values = [opening]

    def move(self, name: str, retimed: Retimed, free: tuple | None = None) -> None:
        """Append an arm motion (`free`: the free path it retimes, with whether it needed
        collision constraints, for its timing record)."""
        self.pieces.append(retimed.trajectory())
        self.q_end = retimed.end
        kto, constrained = (None, False) if free is None else (free[0].end_time(), free[1])
        self.motions.append(
            MotionTiming(name, self.t, retimed.duration, retimed.optimal_duration, kto, constrained)
        )
        self.t += retimed.duration

    def wait(self, duration: float) -> None:
        """Append the arm holding still for `duration` (nothing for none)."""
        if duration <= 0.0:
            return
        q = self.q_end.reshape(-1, 1)
        self.pieces.append(PiecewisePolynomial.ZeroOrderHold([0.0, duration], np.hstack([q, q])))
        self.t += duration

    def gripper(self, opening: float, duration: float) -> None:
        """The gripper goes to `opening` over `duration`, the arm still."""
        self.gripper_times.append(self.t)
        self.gripper_values.append(self.gripper_values[-1])
        self.wait(duration)
        self.gripper_times.append(self.t)
        self.gripper_values.append(opening)

    def ramp_gripper(self, since: float, opening: float) -> None:
        """The gripper goes to `opening` over the arm's motions since plan time `since` (no
        wait: the fingers move while the arm does)."""
        self.gripper_times += [since, self.t]
        self.gripper_values += [self.gripper_values[-1], opening]

    def stage(self, stage: Stage, start: float) -> None:
        """Record `stage` from plan time `start` until now."""
        self.segments.append(Segment(stage, start, self.t))

    def phase(self, start: float, layout: Layout, allowed: tuple[tuple[str, str], ...]) -> None:
        """Record a check phase from plan time `start` until now: the layout to check the
        motion in, and the contacts allowed."""
        self.phases.append(CheckPhase(start, self.t, layout, allowed))

    def trajectory(self) -> CompositeTrajectory:
        """The arm's trajectory so far, one piece per motion or still interval."""
        return CompositeTrajectory.AlignAndConcatenate(self.pieces)

    def gripper_trajectory(self) -> PiecewisePolynomial:
        """The gripper's opening over the plan, linear between its recorded openings."""
        times = [*self.gripper_times, self.t]
        values = [*self.gripper_values, self.gripper_values[-1]]
        keep = [0] + [i for i in range(1, len(times)) if times[i] > times[i - 1] + 1e-9]
        return PiecewisePolynomial.FirstOrderHold(
            np.array([times[i] for i in keep]), np.array([[values[i] for i in keep]])
        )
