"""Grasp/place poses, inverse kinematics, collision-free trajectories, plan validation.

Entry point: `MotionPlanner().plan_task(configuration, task, last_token=...)` returns a `Plan`;
`validate_plan(plan, planner)` checks it.
"""

from hrc_drake.motion.ik import UnreachableError
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.plan import Plan, Segment, Stage
from hrc_drake.motion.planner import MotionPlanner, resolve_task
from hrc_drake.motion.trajectory import PlanningError
from hrc_drake.motion.validate import (
    InvalidPlanError,
    ValidationReport,
    check_plan,
    validate_plan,
)

__all__ = [
    "InvalidPlanError",
    "MotionOptions",
    "MotionPlanner",
    "Plan",
    "PlanningError",
    "Segment",
    "Stage",
    "UnreachableError",
    "ValidationReport",
    "check_plan",
    "resolve_task",
    "validate_plan",
]
