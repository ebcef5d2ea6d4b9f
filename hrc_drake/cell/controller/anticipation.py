"""The robot that moves on its prediction: where along a committed task it can turn to the task
the operator indicates, and how (`turn_at`; `Anticipation`, a part of
`hrc_drake.cell.controller.supervisor.Supervisor`, acts on it).

In ``anticipate`` mode (`hrc_drake.tasks.interaction`) the Supervisor starts, at a boundary, on
the placement its policy commits to, while the operator's indication is still on its way. When
the indication names another task:

- for the same kind of part on another seat (a *re-target*), the robot does not slow down: it
  goes on along its plan, picking the part if it has not yet, to the plan's next rest point —
  the lift's end, or once past it the pre-place pose — and there starts on a plan that carries
  the part on to the indicated seat. That plan is asked for the moment the indication comes,
  from the rest point's posture, and made while the arm moves there (`turn_point`);
- for another part (a *swap*), the robot decelerates along its path and, once still, turns:
  before the fingers close on the part it plans the indicated task from where the arm stands
  (the part it went for stays in the tray); while the fingers close and the part is lifted it
  goes on to the lift's end; carrying, it plans from where it stands back to the part's tray
  home, after which it does the indicated task from above it (`back_above`), not by way of
  home.

A robot that reaches the pre-place pose before the indication waits there, holding the part
above the predicted seat; an indication that comes then turns from there.

This module is the one writer of anticipation's record in the status, `TurnState`: the other
parts change it only through the functions at its end.
"""

from __future__ import annotations

import enum
from dataclasses import replace

from hrc_drake.cell.controller.follower import Stand, hold
from hrc_drake.cell.controller.planning import PlanAsker
from hrc_drake.cell.controller.question import answered
from hrc_drake.cell.controller.supervisor_state import Mode, SupervisorError, SupervisorStatus
from hrc_drake.cell.ports import CellConfiguration
from hrc_drake.motion.plan import HOME_LEG, LIFT, Plan, Stage
from hrc_drake.motion.plan_request import PlanRequest
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.protocols import Commits, PredictsTasks
from hrc_drake.tasks.tokens import UNDO


class Turn(enum.Enum):
    """What a turn to another task does, by where the robot is along its plan."""

    REPLAN = "replan"  # nothing in the gripper yet: plan the indicated task from here
    LATER = "later"  # the fingers are closing or lifting the part: turn at the lift's end
    RETARGET = "retarget"  # the same part: on to the indicated seat from the next rest point
    RETURN = "return"  # carrying: back to the tray home, then the indicated task
    TOO_LATE = "too-late"  # the part is going down onto its seat: nothing to turn


TAU_EPS = 1e-9  # s of plan time: a robot held at a plan time is at it, not past it
# Re-targets asked ahead at a commitment (each a held plan, 0.16-0.19 s of planning on the
# median here: benchmarks/reports/retarget.md; the lift's end comes 2.4 s into a plan).
RETARGETS_AHEAD = 2


def lift_end(plan: Plan) -> float:
    """Plan time at which the part is clear of where it was picked (the carry's own motion
    starts); 0 for a plan that starts with the part held."""
    carry = plan.segment(Stage.CARRY)
    lifts = [m for m in plan.motions if m.name == LIFT]
    return carry.start + (lifts[0].duration if lifts else 0.0)


def wait_point(plan: Plan) -> float:
    """Plan time at the pre-place pose, where a robot still without its indication waits."""
    return plan.segment(Stage.PLACE).start


def back_above(plan: Plan) -> float:
    """Plan time at which a plan that puts a part back in its tray has let it go and risen
    above it (where its last motion, home, starts): a swap goes on from there to the indicated
    task, not by way of home."""
    homeward = [m for m in plan.motions if m.name == HOME_LEG]
    return homeward[-1].start if homeward else plan.duration


def turn_at(plan: Plan, tau: float, spec: AssemblySpec, indicated: str) -> Turn:
    """How the robot at plan time `tau` turns from `plan` to the `indicated` task (another
    one: a plan turned to its own task, after an obstacle appeared, is a `REPLAN`, `LATER`
    or `RETURN` by where the robot is)."""
    if tau > wait_point(plan) + TAU_EPS:
        return Turn.TOO_LATE
    if indicated != plan.task and same_part(spec, plan.task, indicated):
        return Turn.RETARGET
    if tau < plan.segment(Stage.GRASP).start:
        return Turn.REPLAN
    if tau < lift_end(plan):
        return Turn.LATER
    return Turn.RETURN


def turn_point(plan: Plan, tau: float) -> float:
    """The plan time at which a robot at `tau` re-targets: the plan's next rest point, where
    its motions meet and the arm is still — the lift's end (the part clear of the tray), or
    once past it the pre-place pose."""
    end = lift_end(plan)
    return end if tau <= end + TAU_EPS else wait_point(plan)


def same_part(spec: AssemblySpec, committed: str, indicated: str) -> bool:
    """Whether two tasks move the same kind of part (undo moves the part placed last)."""
    if UNDO in (committed, indicated):
        return False
    return spec.placement(committed).part == spec.placement(indicated).part


class Anticipation:
    """The Supervisor's anticipation (a part of
    `hrc_drake.cell.controller.supervisor.Supervisor`): commit, take the indication while
    moving, turn. It asks the planner through the `PlanAsker` it is given and keeps its own
    record, `TurnState`, in the status."""

    def __init__(self, space: StateSpace, policy: Policy, asker: PlanAsker):
        self._space, self._policy, self._asker = space, policy, asker

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The placement the policy bets on (its `commit`; a policy without one bets on its
        proposal when that is a placement)."""
        if isinstance(self._policy, Commits):
            return self._policy.commit(state, proposal)
        return None if proposal == UNDO else proposal

    def on_indication(self, s: SupervisorStatus, indicated: str, now: float) -> SupervisorStatus:
        """Moving on its commitment, the indication came: another task than the committed one
        is turned to (`turn`) once the robot can."""
        event = f"{now:.2f}: step {s.step}: operator indicates {indicated}"
        s = answered(s.noted(event), now)
        s = replace(s, turn=replace(s.turn, awaiting=False))
        committed = s.turn.committed
        if indicated == committed:
            return s
        same = same_part(self._space.spec, committed, indicated)
        return replace(s, turn=replace(s.turn, change=indicated, retargeted=same, swapped=not same))

    def pause_at(self, s: SupervisorStatus, tau: float, limit: float) -> Stand | None:
        """Where the arm at plan time `tau` stands as it reaches the pre-place pose: with no
        indication yet it waits there above the seat (at `limit`); with another part indicated
        it stops there to turn, at rest (slowing down along the path took it on down to the
        seat, too late to turn: the run stopped; population sweep). None: it goes on."""
        plan = s.plan
        above = wait_point(plan)
        if not (tau >= above and s.clock.tau <= above + TAU_EPS):
            return None
        if s.turn.awaiting:
            return Stand(above, limit)
        change = s.turn.change
        if change is not None and not same_part(self._space.spec, plan.task, change):
            return Stand(above, 0.0)
        return None

    def stopping_to_turn(self, s: SupervisorStatus, now: float) -> bool:
        """Whether the robot decelerates to turn to another task (not while its fingers
        close on the part or lift it, nor on its way to a re-target's rest point)."""
        change = s.turn.change
        if change is None or s.mode != Mode.EXECUTE or s.plan is None:
            return False
        turn = turn_at(s.plan, s.plan_time(now), self._space.spec, change)
        return turn not in (Turn.LATER, Turn.RETARGET)

    def turn(
        self, s: SupervisorStatus, config: CellConfiguration, now: float
    ) -> SupervisorStatus | None:
        """Turn to the indicated task `s.turn.change`: before the robot moves, ask for its plan
        instead; once it stands still on its path, plan from there (with the part it holds:
        on to the indicated seat, or back to its tray home). None while it cannot yet."""
        indicated, last = s.turn.change, (s.state[-1] if s.state else None)
        if s.mode in (Mode.PLAN, Mode.BLOCKED):
            s = replace(s, turn=replace(s.turn, change=None))
            return self._asker.ask_task(s, indicated, config, now)
        if s.mode != Mode.EXECUTE:
            return None
        plan, tau = s.plan, s.plan_time(now)
        turn = turn_at(plan, tau, self._space.spec, indicated)
        if turn == Turn.TOO_LATE:
            raise SupervisorError(
                f"step {s.step}: the operator indicated {indicated} after {plan.instance} was "
                "placed; the task is handed over"
            )
        if turn == Turn.RETARGET:
            return self._retarget_on_the_way(s, config, now)
        if turn == Turn.LATER or s.clock.speed > 0.0:
            return None
        q = tuple(float(x) for x in plan.trajectory.value(tau).ravel())
        opening = plan.gripper_opening(tau)
        if turn == Turn.REPLAN:
            # The fingers may stand open by the part it went for: they keep that opening
            # until the arm is clear of it.
            layout, keywords = config.layout(), {"start": q, "start_opening": opening}
        else:
            layout = {i: t for i, t in config.layout().items() if i != plan.instance}
            keywords = {"instance": plan.instance, "start": q, "held": True}
        task = UNDO if turn == Turn.RETURN else indicated
        request = PlanRequest.of(
            s.tokens_before, task, last, layout, obstacle=config.obstacle, **keywords
        )
        event = f"{now:.2f}: turns to {indicated} ({turn.value}) at {tau:.2f} s into its plan"
        s = hold(s.noted(event), q, opening)
        s = replace(s, turn=replace(s.turn, change=None, returning=turn == Turn.RETURN))
        return self._asker.ask(s, request, now)

    def _retarget_request(
        self, s: SupervisorStatus, turn: float, task: str, config: CellConfiguration
    ) -> PlanRequest:
        """The plan of a re-target to `task` from plan time `turn` of the committed plan, with
        its part in the gripper (the cell as it is but that part)."""
        plan = s.plan
        q = tuple(float(x) for x in plan.trajectory.value(turn).ravel())
        layout = {i: t for i, t in config.layout().items() if i != plan.instance}
        return PlanRequest.of(
            s.tokens_before,
            task,
            s.state[-1] if s.state else None,
            layout,
            obstacle=config.obstacle,
            instance=plan.instance,
            start=q,
            held=True,
        )

    def plan_retargets(self, s: SupervisorStatus, config: CellConfiguration) -> SupervisorStatus:
        """Starting on a commitment: ask ahead for the re-targets from the lift's end to the
        other seats the same part may be indicated to (`RETARGETS_AHEAD`, the policy's
        predictions first; none when the run does not plan ahead), so that a re-target
        indicated before the lift's end finds its plan ready there. One indicated later, while
        carrying, is planned during the carry. Returns the status noting what was asked."""
        if not self._asker.plan_ahead:
            return s
        committed, space = s.plan.task, self._space
        feasible = [t for t, _ in space.tasks(space.index(s.state))]
        policy = self._policy
        likely = list(policy.predicted_tasks(s.state)) if isinstance(policy, PredictsTasks) else []
        others = [
            t
            for t in dict.fromkeys([*likely, *feasible])
            if t in feasible and t != committed and same_part(space.spec, committed, t)
        ]
        asked = set()
        for task in others[:RETARGETS_AHEAD]:
            try:
                request = self._retarget_request(s, lift_end(s.plan), task, config)
                self._asker.plans.request(request)
            except ValueError:
                continue  # a layout this task cannot be planned in: asked at the indication
            asked.add(request.key())
        return replace(s, turn=replace(s.turn, retargets_ahead=frozenset(asked)))

    def _retarget_on_the_way(
        self, s: SupervisorStatus, config: CellConfiguration, now: float
    ) -> SupervisorStatus:
        """The same part to another seat: ask now for the plan from the next rest point of the
        committed plan (`turn_point`) on to the indicated seat, with the part in the gripper,
        and go on there; at the rest point, start on it (the arm still, as the plan's own
        motions leave it there)."""
        plan, tau, turning = s.plan, s.plan_time(now), s.turn
        if turning.turn_tau is None:
            turn = turn_point(plan, tau)
            request = self._retarget_request(s, turn, turning.change, config)
            self._asker.plans.request(request)  # made while the arm goes on (or asked ahead)
            where = "the lift's end" if turn < wait_point(plan) else "the pre-place pose"
            event = (
                f"{now:.2f}: re-targets to {turning.change} at {where} ({turn:.2f} s into its "
                "plan), without slowing down"
            )
            return replace(
                s.noted(event), turn=replace(turning, turn_tau=turn, turn_request=request)
            )
        if tau < turning.turn_tau - TAU_EPS:
            return s
        q = tuple(float(x) for x in plan.trajectory.value(turning.turn_tau).ravel())
        s = hold(s, q, plan.gripper_opening(turning.turn_tau))
        s = replace(s, turn=replace(turning, change=None, turn_tau=None, turn_request=None))
        ready = turning.turn_request.key() in turning.retargets_ahead
        return self._asker.ask(s, turning.turn_request, now, plan_ready=ready)


def committed_to(s: SupervisorStatus, committed: str | None) -> SupervisorStatus:
    """`s` at a task boundary: on its way to `committed` (None: waiting for the indication)."""
    turn = replace(
        s.turn,
        committed=committed,
        awaiting=committed is not None,
        change=None,
        retargeted=False,
        swapped=False,
        returning=False,
    )
    return replace(s, turn=turn)


def plan_started(s: SupervisorStatus, plan: Plan) -> SupervisorStatus:
    """`s` starting on `plan`: putting a part back, the arm stops above it, where the indicated
    task starts (`back_above`)."""
    turn_tau = back_above(plan) if s.turn.returning else None
    return replace(s, turn=replace(s.turn, turn_tau=turn_tau))


def dropped(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with its commitment dropped (no plan for it): it waits for the indication."""
    return replace(s, turn=replace(s.turn, committed=None, awaiting=False))


def putting_back(s: SupervisorStatus) -> SupervisorStatus:
    """`s` carrying the part it holds back to its tray first."""
    return replace(s, turn=replace(s.turn, returning=True))


def put_back(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with the part it carried back in its tray: the indicated task is next."""
    return replace(s, turn=replace(s.turn, returning=False, turn_tau=None))


def turn_to(s: SupervisorStatus, task: str) -> SupervisorStatus:
    """`s` turning to `task` once it can (`Anticipation.turn`; the same task: planned again
    from where the arm stops, as after an obstacle appeared)."""
    return replace(s, turn=replace(s.turn, change=task))


def cancelled(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with no turn ahead and nothing awaited (the task is handed over)."""
    return replace(s, turn=replace(s.turn, change=None, awaiting=False))


__all__ = [
    "Anticipation",
    "Turn",
    "back_above",
    "cancelled",
    "committed_to",
    "dropped",
    "lift_end",
    "plan_started",
    "put_back",
    "putting_back",
    "same_part",
    "turn_at",
    "turn_point",
    "turn_to",
    "wait_point",
]
