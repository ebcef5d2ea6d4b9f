"""Check a plan by sampling it: clearance, joint position and velocity limits, tcp speed.

Shared by the tests and the runtime: `check_plan` returns a report, `validate_plan` raises.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.scene import Layout, PlanningScene
from hrc_drake.motion.trajectory import JointLimits


class SceneSource(Protocol):
    """What validation needs from a planner: scenes by layout, joint limits, options."""

    options: MotionOptions
    limits: JointLimits

    def scene(self, layout: Layout) -> PlanningScene: ...


class InvalidPlanError(RuntimeError):
    """A plan breaks a clearance, joint or speed limit."""


@dataclass(frozen=True)
class ValidationReport:
    """What sampling a plan found.

    Attributes:
        ok: every check passed.
        samples: number of sample times.
        min_distance: the smallest robot clearance [m], outside allowed contacts.
        closest_pair: the bodies at that distance, "model::body vs model::body".
        min_distance_time: when [s].
        max_velocity_ratio: the largest |q̇_i| / limit_i.
        max_tcp_speed: the largest tcp speed [m/s].
        max_position_excess: how far a joint goes past its limits [rad] (0 when inside).
        problems: one line per failed check.
    """

    ok: bool
    samples: int
    min_distance: float
    closest_pair: str
    min_distance_time: float
    max_velocity_ratio: float
    max_tcp_speed: float
    max_position_excess: float
    problems: tuple[str, ...]


def check_plan(plan: Plan, scenes: SceneSource, *, rate: float | None = None) -> ValidationReport:
    """Sample `plan` at `rate` Hz (default: the options' validation rate, ≥ 100 Hz) and check it."""
    options = scenes.options
    limits = scenes.limits
    rate = options.validation_rate if rate is None else rate
    n = int(np.ceil(plan.duration * rate)) + 1
    times = np.linspace(0.0, plan.duration, n)
    qdots = plan.trajectory.EvalDerivative  # bound once; called per sample
    worst = (np.inf, "", 0.0)
    max_ratio, max_speed, max_excess = 0.0, 0.0, 0.0
    phase_index = 0
    phases = plan.phases
    for t in times:
        while phase_index < len(phases) - 1 and t > phases[phase_index].end + 1e-9:
            phase_index += 1
        phase = phases[phase_index]
        scene = scenes.scene(phase.layout)
        scene.set_allowed_contacts(phase.allowed_contacts)
        q = plan.trajectory.value(t).ravel()
        qdot = qdots(t, 1).ravel()
        d, pair = scene.min_distance(q)
        if d < worst[0]:
            worst = (d, pair, float(t))
        max_ratio = max(max_ratio, float(np.max(np.abs(qdot) / limits.velocity)))
        excess = np.maximum(limits.lower - q, q - limits.upper)
        max_excess = max(max_excess, float(np.max(excess)))
        J = scene.plant.CalcJacobianTranslationalVelocity(
            scene.plant_context,
            JacobianWrtVariable.kV,
            scene.tcp_frame,
            np.zeros(3),
            scene.plant.world_frame(),
            scene.plant.world_frame(),
        )
        max_speed = max(max_speed, float(np.linalg.norm(J @ qdot)))
    for scene_layout in {p.layout for p in phases}:
        scenes.scene(scene_layout).set_allowed_contacts(())
    problems = []
    if worst[0] < options.clearance:
        problems.append(
            f"clearance {worst[0] * 1000:.1f} mm < {options.clearance * 1000:.1f} mm between "
            f"{worst[1]} at t = {worst[2]:.2f} s"
        )
    if max_ratio > 1.0:
        problems.append(f"joint velocity at {max_ratio:.3f} of its limit")
    if max_speed > options.tcp_speed_limit:
        problems.append(f"tcp speed {max_speed:.3f} m/s > {options.tcp_speed_limit} m/s")
    if max_excess > 0.0:
        problems.append(f"joint position {max_excess:.4f} rad past its limit")
    return ValidationReport(
        ok=not problems,
        samples=n,
        min_distance=float(worst[0]),
        closest_pair=worst[1],
        min_distance_time=worst[2],
        max_velocity_ratio=max_ratio,
        max_tcp_speed=max_speed,
        max_position_excess=max_excess,
        problems=tuple(problems),
    )


def validate_plan(
    plan: Plan, scenes: SceneSource, *, rate: float | None = None
) -> ValidationReport:
    """Like check_plan, but raises InvalidPlanError naming the task and what failed."""
    report = check_plan(plan, scenes, rate=rate)
    if not report.ok:
        raise InvalidPlanError(
            f"plan of task {plan.task} ({plan.instance}) from {sorted(plan.configuration)} is "
            "invalid: " + "; ".join(report.problems)
        )
    return report
