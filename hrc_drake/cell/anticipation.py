"""The robot that moves on its prediction: where along a committed task it can turn to the task
the operator indicates, and how (no Drake systems; the Supervisor asks).

In ``anticipate`` mode (`hrc_drake.tasks.interaction`) the Supervisor starts, at a boundary, on
the placement its policy commits to, while the operator's indication is still on its way. When
the indication names another task, the robot decelerates along its path and, once still, turns:

- before the fingers close on the part, it plans the indicated task from where the arm stands
  (the part it went for stays in the tray);
- while the fingers close and the part is lifted, it goes on: it turns once the part is clear
  (the lift's end);
- carrying, it plans from where the arm stands with the part in the gripper: to the indicated
  seat when that task places the same kind of part (a *re-target*), else back to the part's tray
  home (a *swap*), after which it does the indicated task from home.

A robot that reaches the pre-place pose before the indication waits there, holding the part
above the predicted seat.
"""

from __future__ import annotations

import enum

from hrc_drake.motion.plan import Plan, Stage
from hrc_drake.tasks.spec import AssemblySpec
from hrc_drake.tasks.tokens import UNDO


class Turn(enum.Enum):
    """What a turn to another task does, by where the robot is along its plan."""

    REPLAN = "replan"  # nothing in the gripper yet: plan the indicated task from here
    LATER = "later"  # the fingers are closing or lifting the part: turn at the lift's end
    RETARGET = "retarget"  # carrying: on to the indicated seat with the same part
    RETURN = "return"  # carrying: back to the tray home, then the indicated task
    TOO_LATE = "too-late"  # the part is placed: nothing to turn


def lift_end(plan: Plan) -> float:
    """Plan time at which the part is clear of where it was picked (the carry's own motion
    starts); 0 for a plan that starts with the part held."""
    carry = plan.segment(Stage.CARRY)
    lifts = [m for m in plan.motions if m.name == "lift"]
    return carry.start + (lifts[0].duration if lifts else 0.0)


def wait_point(plan: Plan) -> float:
    """Plan time at the pre-place pose, where a robot still without its indication waits."""
    return plan.segment(Stage.PLACE).start


def turn_at(plan: Plan, tau: float, spec: AssemblySpec, indicated: str) -> Turn:
    """How the robot at plan time `tau` turns from `plan` to the `indicated` task."""
    if tau < plan.segment(Stage.GRASP).start:
        return Turn.REPLAN
    if tau < lift_end(plan):
        return Turn.LATER
    if tau >= wait_point(plan):
        return Turn.TOO_LATE
    return Turn.RETARGET if same_part(spec, plan.task, indicated) else Turn.RETURN


def same_part(spec: AssemblySpec, committed: str, indicated: str) -> bool:
    """Whether two tasks move the same kind of part (undo moves the part placed last)."""
    if UNDO in (committed, indicated):
        return False
    return spec.placement(committed).part == spec.placement(indicated).part


__all__ = ["Turn", "lift_end", "same_part", "turn_at", "wait_point"]
