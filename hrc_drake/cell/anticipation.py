"""The robot that moves on its prediction: where along a committed task it can turn to the task
the operator indicates, and how (`turn_at`; the `Anticipation` mixin of
`hrc_drake.cell.supervisor.Supervisor` acts on it).

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
from dataclasses import replace

from hrc_drake.cell.slot_monitor import CellConfiguration
from hrc_drake.cell.supervisor_state import Mode, SupervisorError, SupervisorStatus
from hrc_drake.motion.plan import Plan, Stage
from hrc_drake.motion.service import PlanRequest
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


class Anticipation:
    """The Supervisor's anticipation: commit, take the indication while moving, turn. A mixin
    of `hrc_drake.cell.supervisor.Supervisor` (its `_policy`, `_space`, `_indicated`,
    `_request`, `_ask`)."""

    def _commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The placement the policy bets on (its `commit`; a policy without one bets on its
        proposal when that is a placement)."""
        commit = getattr(self._policy, "commit", None)
        if commit is not None:
            return commit(state, proposal)
        return None if proposal == UNDO else proposal

    def _await_indication(self, s: SupervisorStatus, context, now: float):
        """Moving on its commitment: take the indication when it comes; another task than
        the committed one is turned to (`_turn`) once the robot can."""
        s, indicated = self._indicated(s, context, now)
        if indicated is None:
            return s
        event = f"{now:.2f}: step {s.step}: operator indicates {indicated}"
        s = replace(s, awaiting=False, indicated_at=now, events=(*s.events, event))
        if indicated == s.committed:
            return s
        proposed, _, part = s.pending
        same = same_part(self._space.spec, s.committed, indicated)
        return replace(
            s,
            change=indicated,
            pending=(proposed, indicated, part),
            retargeted=same,
            swapped=not same,
        )

    def _stopping_to_turn(self, s: SupervisorStatus, now: float) -> bool:
        """Whether the robot decelerates to turn to another task (not while its fingers
        close on the part or lift it)."""
        if s.change is None or s.mode != Mode.EXECUTE or s.plan is None:
            return False
        return turn_at(s.plan, s.plan_time(now), self._space.spec, s.change) != Turn.LATER

    def _turn(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """Turn to the indicated task `s.change`: before the robot moves, ask for its plan
        instead; once it stands still on its path, plan from there (with the part it holds:
        on to the indicated seat, or back to its tray home). None while it cannot yet."""
        indicated, last = s.change, (s.state[-1] if s.state else None)
        if s.mode in (Mode.PLAN, Mode.BLOCKED):
            return self._request(replace(s, change=None), indicated, config, now)
        if s.mode != Mode.EXECUTE or s.speed > 0.0:
            return None
        plan, tau = s.plan, s.plan_time(now)
        turn = turn_at(plan, tau, self._space.spec, indicated)
        if turn == Turn.LATER:
            return None
        if turn == Turn.TOO_LATE:
            raise SupervisorError(
                f"step {s.step}: the operator indicated {indicated} after {plan.instance} was "
                "placed; the task is handed over"
            )
        q = tuple(float(x) for x in plan.trajectory.value(tau).ravel())
        if turn == Turn.REPLAN:
            layout, keywords = config.layout(), {"start": q}
        else:
            layout = {i: t for i, t in config.layout().items() if i != plan.instance}
            keywords = {"instance": plan.instance, "start": q, "held": True}
        task = UNDO if turn == Turn.RETURN else indicated
        request = PlanRequest.of(
            s.tokens_before, task, last, layout, obstacle=config.obstacle, **keywords
        )
        event = f"{now:.2f}: turns to {indicated} ({turn.value}) at {tau:.2f} s into its plan"
        return self._ask(
            s,
            request,
            plan=None,
            q_hold=q,
            opening_hold=plan.gripper_opening(tau),
            change=None,
            returning=turn == Turn.RETURN,
            events=(*s.events, event),
        )


__all__ = ["Anticipation", "Turn", "lift_end", "same_part", "turn_at", "wait_point"]
