"""Grasp/place poses, inverse kinematics, collision-free trajectories, plan validation.

Entry point: `MotionPlanner().plan_task(configuration, task, last_token=...)` returns a `Plan`;
`validate_plan(plan, planner)` checks it.

The names below are loaded on first use, so that the Drake-free `hrc_drake.motion.options`
(`MotionOptions`, whose defaults the scenario schema reads) can be imported without pydrake.
"""

from __future__ import annotations

import importlib

_HOMES = {
    "UnreachableError": "ik",
    "MotionOptions": "options",
    "Plan": "plan",
    "Segment": "plan",
    "Stage": "plan",
    "MotionPlanner": "planner",
    "resolve_task": "task_move",
    "PlanningError": "trajectory",
    "InvalidPlanError": "validate",
    "ValidationReport": "validate",
    "check_plan": "validate",
    "validate_plan": "validate",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
