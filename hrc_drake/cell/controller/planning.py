"""The Supervisor's side of the planner: asking for a task's plan (the arm holds still until the
planner answers) and planning ahead what the policy will propose next. The planner itself runs
beside the controller, behind a `PlanService` (`hrc_drake.motion.service`). This module is the
one writer of the planner's record in the status, `PlanAsk`."""

from __future__ import annotations

import time
from dataclasses import replace

from hrc_drake.cell.controller.supervisor_state import Event, SupervisorStatus
from hrc_drake.cell.ports import CellConfiguration
from hrc_drake.motion.plan_request import PlanRequest
from hrc_drake.motion.service import PlanService
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.protocols import PredictsTasks
from hrc_drake.tasks.tokens import UNDO


class PlanAsker:
    """Asks `plans` for the Supervisor's plans; with `plan_ahead`, also for what the policy
    will propose at the next boundary (made while the robot works)."""

    def __init__(
        self, plans: PlanService, space: StateSpace, policy: Policy, plan_ahead: bool = True
    ):
        self.plans, self._space, self._policy, self.plan_ahead = plans, space, policy, plan_ahead

    def ask(
        self,
        s: SupervisorStatus,
        request: PlanRequest,
        now: float,
        plan_ready: bool | None = None,
    ) -> SupervisorStatus:
        """Ask the planner for `request` at simulated time `now`; the arm holds still until it
        answers (Mode.PLAN). `plan_ready`: whether the plan was made ahead (None: as noted)."""
        self.plans.request(request)
        ask = replace(s.ask, request=request, requested_at=now, requested_wall=time.perf_counter())
        if plan_ready is not None:
            ask = replace(ask, plan_ready=plan_ready)
        return replace(s, ask=ask).enter(Event.PLAN_ASKED)

    def ask_task(
        self,
        s: SupervisorStatus,
        task: str,
        config: CellConfiguration,
        now: float,
        start: tuple[float, ...] | None = None,
    ) -> SupervisorStatus:
        """Ask the planner for `task` from the boundary's layout, the arm at home (or at rest
        at `start`, the gripper at its held opening there)."""
        last = s.state[-1] if s.state else None
        if start is None and s.recovery.away:  # after a handover the arm holds where it stopped
            start = s.q_hold
        request = PlanRequest.of(
            s.tokens_before,
            task,
            last,
            config.layout(),
            obstacle=config.obstacle,
            start=start,
            start_opening=None if start is None else s.opening_hold,
        )
        return self.ask(s, request, now, plan_ready=self.plans.is_cached(request))

    def plan_ahead_after(self, s: SupervisorStatus, config: CellConfiguration) -> None:
        """While the operator bolts: plan what the policy will propose once this task is done
        (the layout as it will be if the part stays where it is placed)."""
        task = s.task
        layout = config.layout()
        if task.indicated == UNDO:
            layout.pop(task.part, None)
            state = s.state[:-1]
        else:
            layout[task.part] = task.indicated
            state = (*s.state, task.indicated)
        self.plan_ahead_of(state, layout)

    def plan_ahead_of(self, state: tuple[str, ...], layout: dict[str, str]) -> None:
        """Ask for the plans of the tasks the policy predicts in `state` (most likely first),
        the cell laid out as `layout`; none in a terminal state or when not planning ahead."""
        if not self.plan_ahead:
            return
        space = self._space
        try:
            index = space.index(state)
        except KeyError:
            return
        if space.kind[index] == StateKind.TERMINAL:
            return
        policy = self._policy
        if isinstance(policy, PredictsTasks):
            tasks = policy.predicted_tasks(state)
        else:
            tasks = [policy.next_task(state)]
        last = state[-1] if state else None
        for task in (t for t in tasks if t is not None):
            try:
                self.plans.request(PlanRequest.of(layout.values(), task, last, layout))
            except ValueError:
                continue  # a prediction the layout cannot serve: the boundary will tell


def plan_taken(s: SupervisorStatus, now: float) -> SupervisorStatus:
    """`s` with the wait for the plan that came at `now` counted against its task."""
    ask = s.ask
    idle, wall_idle = now - ask.requested_at, time.perf_counter() - ask.requested_wall
    return replace(s, ask=replace(ask, idle=idle, wall_idle=wall_idle))


def task_closed(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with no request in flight (the task is read: the next one asks afresh)."""
    return replace(s, ask=replace(s.ask, request=None))


__all__ = ["PlanAsker", "plan_taken", "task_closed"]
