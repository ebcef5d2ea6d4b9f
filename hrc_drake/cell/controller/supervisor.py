"""The Supervisor: at every task boundary it reads the cell, asks the policy, and drives the robot.

It is the controller's task level and sees the cell only through what a real cell measures
(`docs/station.md`). At a task boundary the Supervisor
1. reads the configuration sensor and, with the history it has seen, the MDP state;
2. asks the policy for the next task and shows it on the operator's interface (a `CHOOSE`
   prompt);
3. takes the operator's indication (the proposal confirmed, or another task);
4. asks the planner for the plan — the planner runs beside it (`hrc_drake.motion.service`): the
   update only asks and polls, holding the arm still meanwhile — and drives the UR3 and the
   gripper through it: pick, carry, place; holds the part still and prompts `BOLT`; once the
   operator says it is bolted, releases and retreats (or, for `undo`, takes the part placed
   last back to the tray);
5. after the task, learns what really happened from the configuration sensor — the part may
   sit in another seat than planned — and only then moves the MDP state on.

It checks what it commands against what it measures: a joint farther from its command than
`station.ur3.tracking_tolerance`, fingers that do not stand at the width of the part they
should hold (and have not stalled on it), or that have not left it after the release, stop the
task with the reason, and the run. A protective stop on the `safety.stop` input stops the robot
on its path until it clears; an operator silent for `run.indication_timeout` is asked again,
and after `run.indication_give_up` the run stops. A task with no path while the configuration
sensor sees an obstacle waits for it to move or go, planning again each time it does, for up to
`run.path_timeout`. A task the robot cannot do while it is itself sound (a part it dropped and
cannot pick again, a path that stays blocked) is handed over: the arm holds still, the
interface prompts `HANDOVER`, the operator does the task by hand and says so, and the robot
reads the cell and goes on (`hrc_drake.cell.controller.recovery`). Each is recorded as a `Detection`
(what the run reports of the scenario's faults, `hrc_drake.cell.run.fault_report`).

In `anticipate` mode it does not wait at step 3: it starts on the placement its policy commits
to and turns when the indication names another task (`hrc_drake.cell.controller.anticipation`). With
predictive separation it times its plan's moves around its forecast of the operator
(`hrc_drake.cell.controller.keep_clear`). The fault handling is
`hrc_drake.cell.controller.recovery`; the Supervisor's values (its mode, state, records and limits)
are `hrc_drake.cell.controller.supervisor_state`.

The robot follows its plan in plan time `tau`, which advances at the speed scale s ∈ [0, 1] that
the separation monitor allows on the optional `speed_limit` input: the robot slows down by
scaling its trajectory's time, stops with s = 0 and resumes as s ramps back, never faster than
the arm's joint acceleration limit allows. While it holds a part for bolting, `tau` stands at
the start of the plan's hold; the operator's `bolted` moves it to the release.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.controller.anticipation import (
    TAU_EPS,
    Anticipation,
    back_above,
    same_part,
    wait_point,
)
from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.keep_clear import KeepClear, KeepClearSettings
from hrc_drake.cell.controller.recovery import FaultRecovery
from hrc_drake.cell.controller.supervisor_state import (
    N_JOINTS,
    TASK_CAP,
    Detection,
    Mode,
    SupervisorError,
    SupervisorLimits,
    SupervisorStatus,
    TaskRecord,
)
from hrc_drake.cell.ports import CellConfiguration, PartStatus
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.plan_request import PlanFailure, PlanRequest
from hrc_drake.motion.service import PlanService
from hrc_drake.robot_models import UR3_JOINTS
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.protocols import PredictsTasks
from hrc_drake.tasks.tokens import UNDO


class Supervisor(FaultRecovery, Anticipation, KeepClear, LeafSystem):
    """Task-level state machine of the cell (see the module docstring).

    Input ports: `configuration` (CellConfiguration), `hri.indication` (Indication),
    `ur3.state_estimated` (12), `rg2.state_measured` (2: opening, rate), `rg2.grip_detected`
    (1), `speed_limit` (1: the speed scale the separation monitor allows; unconnected, 1),
    `safety.stop` (1: the robot's protective-stop input; unconnected, none), `operator.body`
    (BodySpheres, the tracked body: predictive separation holds it against its forecast,
    `hrc_drake.cell.controller.keep_clear`; unconnected, nobody).
    Output ports: `command` (14: the arm's joint positions and velocities, then the gripper's
    opening and grip force; the controller splits it into `ur3.position`, `ur3.velocity`,
    `rg2.opening`, `rg2.force`),
    `hri.prompt` (Prompt), `intent` (MotionIntent), `status` (SupervisorStatus).
    `policy` needs `next_task(state)` and `matches(spec)` (a `Policy`, or a decider wrapped by
    `hrc_drake.cell.run.evaluate.DeciderPolicy`), and may offer `predicted_tasks(state)` (most
    likely first) for planning ahead; `on_task(record)`, if given, hears every task as the cell
    observed it (a learning decider updates its operator model from it).
    """

    def __init__(
        self,
        space: StateSpace,
        policy: Policy,
        plans: PlanService,
        home: np.ndarray,
        home_opening: float,
        limits: SupervisorLimits | None = None,
        on_task: Callable[[TaskRecord], None] | None = None,
        keep_clear: KeepClearSettings | None = None,
    ):
        super().__init__()
        policy.matches(space.spec)
        self._space, self._policy, self._plans = space, policy, plans
        self._home = tuple(float(x) for x in home)
        self._limits = limits if limits is not None else SupervisorLimits()
        self._on_task = on_task
        self._declare_inputs()
        clear = keep_clear if keep_clear is not None else KeepClearSettings()
        self._declare_keep_clear(clear)
        initial = SupervisorStatus(
            q_hold=tuple(float(x) for x in home), opening_hold=float(home_opening)
        )
        self._status_index = self.DeclareAbstractState(AbstractValue.Make(initial))
        self._declare_outputs()
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._limits.period, 0.0, self._update)

    def _declare_inputs(self) -> None:
        self._config_port = self.DeclareAbstractInputPort(
            "configuration", AbstractValue.Make(CellConfiguration())
        )
        self._indication_port = self.DeclareAbstractInputPort(
            "hri.indication", AbstractValue.Make(Indication())
        )
        self._arm_port = self.DeclareVectorInputPort("ur3.state_estimated", 2 * N_JOINTS)
        self._gripper_port = self.DeclareVectorInputPort("rg2.state_measured", 2)
        self._grip_port = self.DeclareVectorInputPort("rg2.grip_detected", 1)
        self._speed_port = self.DeclareVectorInputPort("speed_limit", BasicVector(1))
        self._stop_port = self.DeclareVectorInputPort("safety.stop", BasicVector(1))

    def _declare_outputs(self) -> None:
        # Outputs depend on the state and time only (no feedthrough): the separation monitor
        # reads `intent` and feeds `speed_limit` back without an algebraic loop.
        deps = {self.time_ticket(), self.abstract_state_ticket(self._status_index)}
        # One command, evaluated once per plant step, split into the arm's and the gripper's.
        self.DeclareVectorOutputPort(
            "command", 2 * N_JOINTS + 2, self._calc_command, prerequisites_of_calc=deps
        )
        for name, empty, calc in (
            ("hri.prompt", Prompt(), self._calc_prompt),
            ("intent", MotionIntent(), self._calc_intent),
            ("status", SupervisorStatus(), self._calc_status),
        ):
            self.DeclareAbstractOutputPort(
                name,
                lambda empty=empty: AbstractValue.Make(empty),
                calc,
                prerequisites_of_calc=deps,
            )

    # --- outputs -------------------------------------------------------------------------
    def _status(self, context) -> SupervisorStatus:
        return context.get_abstract_state(self._status_index).get_value()

    def _calc_command(self, context, output) -> None:
        q, v, opening = self._status(context).command(context.get_time())
        # The gripper always grips with the scenario's force (a real RG2 takes one with every
        # target width); the opening says whether it closes on a part.
        output.SetFromVector(np.concatenate([q, v, [opening, self._limits.grip_force]]))

    def _calc_prompt(self, context, output) -> None:
        output.set_value(self._status(context).prompt)

    def _calc_status(self, context, output) -> None:
        output.set_value(self._status(context))

    def _calc_intent(self, context, output) -> None:
        s = self._status(context)
        if s.mode != Mode.EXECUTE or s.plan is None:
            output.set_value(MotionIntent(rate=s.rate))
            return
        now = context.get_time()
        plan, tau = s.plan, s.plan_time(now)
        carrying = plan.carrying(tau)
        if s.held(now):  # a planned wait for the operator: the arm stands still
            output.set_value(MotionIntent(carrying=carrying, moving=False, rate=s.rate))
            return
        moving = tau < plan.duration and not s.holding_for_bolts(tau) and s.rate > 0
        qdot = plan.trajectory.EvalDerivative(min(tau, plan.duration), 1).ravel()
        output.set_value(
            MotionIntent(
                qdot=qdot if tau < plan.duration else np.zeros_like(qdot),
                carrying=carrying,
                moving=moving,
                rate=s.rate,
            )
        )

    # --- the state machine ---------------------------------------------------------------
    def _update(self, context, state) -> None:
        status = self._status(context)
        now = context.get_time()
        limit = self._speed_port.Eval(context)[0] if self._speed_port.HasValue(context) else 1.0
        stop = self._stop_port.HasValue(context) and self._stop_port.Eval(context)[0] > 0.5
        status = self._note_stop(status, stop, now)
        if stop or self._stopping_to_turn(status, now):
            limit = 0.0  # decelerate along the path, as for the separation monitor's stop
        try:
            self._check_tracking(status, context, now)
            status = self._advance(status, float(np.clip(limit, 0.0, 1.0)), now)
            status = self._step(status, context, now)
            status = self._keep_clear(status, context, now)
        except SupervisorError as err:
            if err.hand_over:
                status = self._hand_over(status, context, now, err)
            else:
                status = self._stop(status, context, now, err)
        state.get_mutable_abstract_state(self._status_index).set_value(status)

    def _stop(self, s: SupervisorStatus, context, now: float, err: SupervisorError):
        """Stop the task: the arm holds where it is measured, the gripper keeps its command
        (a part in it stays held)."""
        q = self._arm_port.Eval(context)[:N_JOINTS]
        opening = s.command(now)[2]
        if err.cause == TASK_CAP:
            s = replace(s, capped=True)
        elif not s.open_detection():
            s = replace(s, detections=(*s.detections, Detection(err.cause, s.step, now)))
        s = self._resolve(s, None, now, "operator")
        return replace(
            s,
            mode=Mode.FAILED,
            error=str(err),
            plan=None,
            q_hold=tuple(float(x) for x in q),
            opening_hold=float(opening),
            events=(*s.events, f"{now:.2f}: stopped: {err}"),
        )

    def _step(self, status: SupervisorStatus, context, now: float) -> SupervisorStatus:
        if status.awaiting and status.mode in (Mode.PLAN, Mode.BLOCKED, Mode.EXECUTE):
            status = self._await_indication(status, context, now)
        if status.mode == Mode.EXECUTE and status.change is None:
            status = self._watch_obstacle(status, self._config_port.Eval(context), now)
        if status.change is not None:
            turned = self._turn(status, self._config_port.Eval(context), now)
            if turned is not None and turned.mode != Mode.EXECUTE:
                return turned
            status = turned or status  # executing: on its way to where it turns
        mode = status.mode
        if mode == Mode.DECIDE:
            return self._decide(status, self._config_port.Eval(context), now)
        if mode == Mode.ASK:
            return self._take_indication(status, context, now)
        if mode == Mode.PLAN:
            return self._take_plan(status, self._config_port.Eval(context), now)
        if mode == Mode.BLOCKED:
            return self._wait_for_path(status, self._config_port.Eval(context), now)
        if mode == Mode.EXECUTE:
            return self._execute(status, context, now)
        if mode == Mode.SETTLE and now >= status.settle_until:
            return self._observe(status, context, now)
        if mode == Mode.RECOVER and now >= status.settle_until:
            return self._pick_again(status, self._config_port.Eval(context), now)
        if mode == Mode.HANDOVER:
            return self._wait_for_operator(status, context, now)
        return status

    def _check_tracking(self, s: SupervisorStatus, context, now: float) -> None:
        """Stop when a joint is farther from its command than the tolerance (the command of
        the previous update, which the servo has had a period to follow)."""
        if s.mode in (Mode.DONE, Mode.FAILED):
            return
        q = self._arm_port.Eval(context)[:N_JOINTS]
        error = np.abs(q - s.command(now)[0])
        worst = int(np.argmax(error))
        if error[worst] > self._limits.tracking_tolerance:
            raise SupervisorError(
                f"step {s.step}: {UR3_JOINTS[worst]} is {error[worst]:.3f} rad from its command "
                f"(tolerance {self._limits.tracking_tolerance} rad): the arm is pushed or "
                "blocked; the task is stopped and the arm holds where it is",
                cause="tracking",
            )

    def _advance(self, s: SupervisorStatus, limit: float, now: float) -> SupervisorStatus:
        """Move the plan time to `now`, then ramp the speed scale toward `limit` (no faster
        than the joint acceleration limit allows at the plan's speed) and set the rate on.
        While the robot holds a part for bolting the plan time stands still."""
        if s.mode != Mode.EXECUTE or s.plan is None:
            return replace(s, speed=limit)
        plan = s.plan
        tau = s.plan_time(now)
        above = wait_point(plan)
        if tau >= above and s.tau <= above + TAU_EPS:  # reaching the pre-place pose
            if s.awaiting:  # no indication yet: wait above the seat
                return replace(s, tau=above, tau_time=now, speed=limit, rate=0.0)
            if s.change is not None and not same_part(self._space.spec, plan.task, s.change):
                # Another part indicated as the arm reaches the pre-place pose, where it is at
                # rest: it stops there to turn. Slowing down along the path took it on down
                # to the seat, too late to turn (the run stopped; population sweep).
                return replace(s, tau=above, tau_time=now, speed=0.0, rate=0.0)
        if s.holding_for_bolts(tau):
            return replace(s, tau=plan.t_in_place, tau_time=now, speed=limit, rate=0.0)
        qdot = np.abs(plan.trajectory.EvalDerivative(min(tau, plan.duration), 1)).max()
        step = self._limits.joint_acceleration * self._limits.period / max(qdot, 1e-9)
        speed = float(np.clip(limit, s.speed - step, s.speed + step))
        hold = s.hold_at(now) if s.held(now) else None  # the planned wait the arm stands in
        since = s.held_since
        if hold is not None and (since is None or since[0] != hold.tau):
            since = (hold.tau, now)
        waited = s.waited + (now - s.tau_time if hold is not None else 0.0)
        return replace(
            s, tau=tau, tau_time=now, speed=speed, rate=speed, waited=waited, held_since=since
        )

    def _decide(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """At a task boundary: the MDP state from the cell, then the policy's proposal on the
        operator's interface."""
        space = self._space
        tokens = config.tokens()
        index = space.index(s.state)
        if tokens != space.configuration(index):
            raise SupervisorError(
                f"the cell shows {sorted(tokens)} but state {list(s.state)} holds "
                f"{sorted(space.configuration(index))}"
            )
        if space.kind[index] == StateKind.TERMINAL:
            return replace(s, mode=Mode.DONE, events=(*s.events, f"{now:.2f}: done"))
        if s.step >= self._limits.max_steps:
            raise SupervisorError(
                f"no terminal state after {s.step} tasks (the run's cap, run.max_steps)",
                cause=TASK_CAP,
            )
        if s.step == 0:
            self._plan_ahead(s.state, config.layout())
        proposal = self._policy.next_task(s.state)
        committed = self._commit(s.state, proposal) if self._limits.anticipate else None
        prompt = Prompt(s.step + 1, PromptKind.CHOOSE, s.state, proposal, committed=committed or "")
        s = replace(
            s,
            mode=Mode.ASK,
            step=s.step + 1,
            prompt=prompt,
            tokens_before=tokens,
            asked_at=now,
            prompted_at=now,
            committed=committed,
            awaiting=committed is not None,
            indicated_at=None,
            held_at=None,
            change=None,
            retargeted=False,
            swapped=False,
            returning=False,
        )
        if committed is None:
            return s
        event = f"{now:.2f}: step {s.step} proposes {proposal}, starts on {committed}"
        s = replace(s, pending=(proposal, committed, ""), events=(*s.events, event))
        return self._request(s, committed, config, now)

    def _request(
        self,
        s: SupervisorStatus,
        task: str,
        config: CellConfiguration,
        now: float,
        start: tuple[float, ...] | None = None,
    ):
        """Ask the planner for `task` from the boundary's layout, the arm at home (or at rest
        at `start`, the gripper at its held opening there)."""
        last = s.state[-1] if s.state else None
        if start is None and s.away:  # after a handover the arm holds where it stopped
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
        return self._ask(s, request, now, plan_ready=self._plans.is_cached(request))

    def _ask(
        self, s: SupervisorStatus, request: PlanRequest, now: float, **changes
    ) -> SupervisorStatus:
        """Ask the planner for `request` at simulated time `now`; the arm holds still until it
        answers (Mode.PLAN). `changes`: other fields of the status to set."""
        self._plans.request(request)
        return replace(
            s,
            mode=Mode.PLAN,
            request=request,
            requested_at=now,
            requested_wall=time.perf_counter(),
            **changes,
        )

    def _indicated(self, s: SupervisorStatus, context, now: float):
        """(status, the task the operator indicated, checked feasible) once the answer to the
        prompt is in; (status noting any silence, None) before."""
        indication: Indication = self._indication_port.Eval(context)
        if not indication.answers(s.prompt):
            return self._note_silence(s, now), None
        s = self._resolve(s, "silence", now, "ask")
        return s, self._feasible(s, indication.task)

    def _take_indication(self, s: SupervisorStatus, context, now: float):
        """Once the operator indicates a task: check it, then ask the planner for it."""
        s, indicated = self._indicated(s, context, now)
        if indicated is None:
            return s
        event = f"{now:.2f}: step {s.step} proposes {s.prompt.proposal}, operator indicates "
        s = replace(
            s,
            indicated_at=now,
            pending=(s.prompt.proposal, indicated, ""),
            events=(*s.events, event + indicated),
        )
        return self._request(s, indicated, self._config_port.Eval(context), now)

    def _feasible(self, s: SupervisorStatus, indicated: str) -> str:
        """The indicated task, if feasible in the state; SupervisorError if not."""
        space = self._space
        feasible = {t for t, _ in space.tasks(space.index(s.state))}
        if indicated not in feasible:
            raise SupervisorError(
                f"step {s.step}: the operator indicated {indicated!r}, not feasible in "
                f"{list(s.state)} (feasible: {sorted(feasible)})"
            )
        return indicated

    def _take_plan(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """Once the planner answers: start the plan (the arm held still until then)."""
        result = self._plans.poll(s.request)
        if result is None:
            return s
        step, (proposed, indicated, _) = s.step, s.pending
        if isinstance(result, PlanFailure) and s.request.obstacle is not None:
            return self._blocked(s, result, now)
        if isinstance(result, PlanFailure) and s.recovering:
            raise SupervisorError(
                f"step {step}: the robot cannot pick {s.pending[2]} from where it lies "
                f"({result.reason}); the task is handed over",
                cause="plan",
                hand_over=True,
            )
        if isinstance(result, PlanFailure):
            raise SupervisorError(f"step {step}: {result}", cause="plan")
        plan: Plan = result
        s = self._resolve(s, "plan", now, "retry")  # a path once the obstacle moved
        placement = config.placement(plan.instance)
        expected = PartStatus.SEATED if indicated == UNDO else PartStatus.TRAY
        if placement.status != expected and not (s.recovering or s.request.held):
            raise SupervisorError(
                f"step {step}: {plan.instance} should be {expected.value} for {indicated}, the "
                f"cell shows it {placement.status.value}"
            )
        started = replace(
            s,
            mode=Mode.EXECUTE,
            plan=plan,
            plan_start=now,
            tau=0.0,
            tau_time=now,
            rate=s.speed,
            pending=(proposed, indicated, plan.instance),
            bolted=False,
            away=False,  # every plan ends at home
            planned_ahead=s.returning,  # a part put back: nothing to plan ahead for yet
            # Putting a part back, the arm stops above it, where the indicated task starts.
            turn_tau=back_above(plan) if s.returning else None,
            holds=(),
            held_since=None,
            idle=now - s.requested_at,
            wall_idle=time.perf_counter() - s.requested_wall,
        )
        if started.awaiting and plan.task == started.committed:
            return self._plan_retargets(started, config)
        return started

    def _execute(self, s: SupervisorStatus, context, now: float):
        """Follow the plan: check the grasp, prompt for the bolts and wait for them, plan the
        next task ahead, and settle at the end."""
        plan = s.plan
        tau = s.plan_time(now)
        s = self._check_grip(s, context, now)
        if s.mode != Mode.EXECUTE:
            return s  # the part was lost: it is picked again once it rests
        if tau >= plan.t_in_place and not s.planned_ahead:
            s = replace(s, planned_ahead=True)
            self._plan_ahead_after(s, self._config_port.Eval(context))
        if s.holding_for_bolts(tau):
            return self._hold_for_bolts(s, context, now)
        above = back_above(plan) if s.returning else None
        if above is not None and tau >= above:  # the part is back: the indicated task
            q = tuple(float(x) for x in plan.trajectory.value(above).ravel())
            opening = plan.gripper_opening(above)
            s = replace(
                s, plan=None, q_hold=q, opening_hold=opening, returning=False, turn_tau=None
            )
            config = self._config_port.Eval(context)
            return self._request(s, s.pending[1], config, now, start=q)
        if tau >= plan.duration:
            q_end = tuple(float(x) for x in plan.trajectory.value(plan.duration).ravel())
            return replace(
                s,
                mode=Mode.SETTLE,
                settle_until=now + self._limits.settle_time,
                q_hold=q_end,
                opening_hold=plan.gripper_opening(plan.duration),
                plan=None,
                prompt=replace(s.prompt, kind=PromptKind.NONE),
            )
        return s

    def _hold_for_bolts(self, s: SupervisorStatus, context, now: float):
        """Hold the part in place: prompt BOLT once; on `bolted`, go on to the release."""
        _proposed, indicated, part = s.pending
        if s.prompt.kind != PromptKind.BOLT:
            prompt = Prompt(s.step, PromptKind.BOLT, s.state, indicated, part)
            event = f"{now:.2f}: holds {part}"
            return replace(s, prompt=prompt, held_at=now, events=(*s.events, event))
        indication: Indication = self._indication_port.Eval(context)
        if not indication.answers(s.prompt):
            return s
        event = f"{now:.2f}: operator has bolted {part}"
        return replace(
            s, bolted=True, tau=s.plan.t_release, tau_time=now, events=(*s.events, event)
        )

    def _plan_ahead_after(self, s: SupervisorStatus, config: CellConfiguration) -> None:
        """While the operator bolts: plan what the policy will propose once this task is done
        (the layout as it will be if the part stays where it is placed)."""
        _proposed, indicated, part = s.pending
        layout = config.layout()
        if indicated == UNDO:
            layout.pop(part, None)
            state = s.state[:-1]
        else:
            layout[part] = indicated
            state = (*s.state, indicated)
        self._plan_ahead(state, layout)

    def _plan_ahead(self, state: tuple[str, ...], layout: dict[str, str]) -> None:
        if not self._limits.plan_ahead:
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
                self._plans.request(PlanRequest.of(layout.values(), task, last, layout))
            except ValueError:
                continue  # a prediction the layout cannot serve: the boundary will tell

    def _observe(self, s: SupervisorStatus, context, now: float):
        """After the task: what the cell shows was done moves the MDP state on. A part let go
        out of any seat is picked again and re-placed (up to `recover_tries` times); then, or
        when the robot cannot pick it, the task is handed over. A task the operator did by
        hand is read the same way (and never handed over again)."""
        proposed, indicated, part = s.pending
        config: CellConfiguration = self._config_port.Eval(context)
        unseated = (
            indicated != UNDO
            and not s.handover
            and config.placement(part).status in (PartStatus.MISPLACED, PartStatus.TRANSIT)
        )
        if unseated and s.recoveries < self._limits.recover_tries:
            return self._lose_part(s, context, now, "seat", "replace")
        observed, next_state = self._observed(s, config)
        if s.handover and not part:  # handed over before the robot chose a part
            part = next((i for i, t in config.layout().items() if t == observed), "")
        if s.recovering:
            for cause in ("grip", "seat"):
                s = self._resolve(s, cause, now, s.recovering)
        s = replace(s, recovering="", recoveries=0)
        record = TaskRecord(
            step=s.step,
            state=s.state,
            proposed=proposed,
            indicated=indicated,
            observed=observed,
            next_state=next_state,
            part=part,
            start_time=s.plan_start,
            end_time=now,
            idle=s.idle,
            wall_idle=s.wall_idle,
            plan_ready=s.plan_ready,
            committed=s.committed,
            indicated_at=s.indicated_at,
            held_at=s.held_at,
            retargeted=s.retargeted,
            swapped=s.swapped,
            handed_over=s.handover,
        )
        if self._on_task is not None:
            self._on_task(record)
        event = f"{now:.2f}: cell shows {observed}; state {' '.join(next_state) or '(start)'}"
        return replace(
            s,
            mode=Mode.DECIDE,
            state=next_state,
            pending=None,
            request=None,
            handover="",
            history=(*s.history, record),
            events=(*s.events, event),
        )

    def _observed(self, s: SupervisorStatus, config: CellConfiguration):
        """(the task the cell shows done, the next MDP state); SupervisorError if the cell
        shows something no task explains."""
        _proposed, indicated, part = s.pending
        tokens = config.tokens()
        added, removed = tokens - s.tokens_before, s.tokens_before - tokens
        if indicated == UNDO:
            if added or removed != {s.state[-1]}:
                raise SupervisorError(
                    f"after undo of {s.state[-1]} the cell shows {sorted(tokens)} (removed "
                    f"{sorted(removed)}, added {sorted(added)})"
                )
            return UNDO, s.state[:-1]
        if removed or len(added) != 1:
            where = config.placement(part).status.value if part else "not placed"
            raise SupervisorError(
                f"after {indicated} the cell shows {sorted(tokens)}: {part or 'its part'} is "
                f"{where}, not in a seat",
                cause="seat",
                # Out of its seat, out of the gripper, nothing else moved: the operator can
                # seat it (unless they did the task already).
                hand_over=not removed and not added and not s.handover,
            )
        (observed,) = added
        if observed not in {t for t, _ in self._space.tasks(self._space.index(s.state))}:
            raise SupervisorError(
                f"the cell shows {observed} placed, not a feasible task from {list(s.state)}"
            )
        return observed, (*s.state, observed)


__all__ = [
    "Detection",
    "Mode",
    "Supervisor",
    "SupervisorError",
    "SupervisorLimits",
    "SupervisorStatus",
    "TaskRecord",
]
