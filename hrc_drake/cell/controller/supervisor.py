"""The Supervisor: at every task boundary it reads the cell, asks the policy, and drives the robot.

It is the controller's task level and sees the cell only through what a real cell measures
(`docs/station.md`). At a task boundary the Supervisor
1. reads the configuration sensor and, with the history it has seen, the MDP state;
2. asks the policy for the next task and shows it on the interface (a `CHOOSE` prompt);
3. takes the operator's indication (the proposal confirmed, or another task);
4. asks the planner (`hrc_drake.motion.service`, beside it) for the plan and drives the arm and
   gripper through it: pick, carry, place; holds the part, prompts `BOLT`; once it is bolted,
   releases and retreats (`undo`: takes the part placed last back to the tray);
5. after the task, learns from the configuration sensor what really happened (the part may sit
   in another seat than planned) and only then moves the MDP state on.

It checks what it commands against what it measures: a joint farther from its command than
`station.ur3.tracking_tolerance`, fingers that do not stand at the width of the part they
should hold (and have not stalled on it), or that have not left it after the release (the arm
waits for them there), stop the task with the reason, and the run. A protective stop on the
`safety.stop` input stops the robot on its path until it clears; an operator silent for
`run.indication_timeout` is asked again, and after `run.indication_give_up` the run stops. A
task with no path while the configuration sensor sees an obstacle waits for it to move or go,
planning again each time it does, for up to `run.path_timeout`. A task the robot cannot do
while it is itself sound (a part it dropped and cannot pick again, a path that stays blocked,
a task it finds no plan for: no IK, a collision, the solver failed) is handed over: the arm
holds still, the interface prompts `HANDOVER`, the operator does the task by hand and says so,
and the robot reads the cell and goes on. Each is recorded as a
`Detection` (what the run reports of the scenario's faults, `hrc_drake.cell.run.fault_report`).

In `anticipate` mode it does not wait at step 3: it starts on the placement its policy commits
to and turns when the indication names another task. With predictive separation it times its
plan's moves around its forecast of the operator.

The Supervisor is composed of parts, each with its own narrow inputs (the status, the update's
`Readings`, the time) and its own record in the status, of which it is the one writer:
`FaultRecovery` (`recovery`: `RecoveryState`, the detections), `Anticipation` (`anticipation`:
`TurnState`), `KeepClear` (`keep_clear`: `KeepClearState`), the `PlanAsker` they share
(`planning`: `PlanAsk`), the operator's interface (`question`: `Question`) and the
`PlanFollower` (`follower`: the plan clock and the arm's command). A part changes another's
record only through that owner's functions; the mode changes only through the table
`supervisor_state.TRANSITIONS` (`SupervisorStatus.enter`); this module writes the task's own
fields (state, step, task, history). Its values (mode, status records, limits) are in
`supervisor_state`; what the cell shows after a task, in `observe`
(`tests/test_record_owners.py` holds each record to its one writer).

The robot follows its plan in plan time `tau`, advancing at the speed scale s ∈ [0, 1] the
separation monitor allows (`speed_limit`): it slows by scaling its trajectory's time, stops at
s = 0 and resumes as s ramps back, within the joint acceleration limit. `tau` stands at the
plan's hold while it holds a part for bolting (`bolted` moves it to the release), and at the
release's end until the fingers have let go.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem, ValueProducer

from hrc_drake.cell.controller import anticipation, follower, planning, question, recovery
from hrc_drake.cell.controller.anticipation import Anticipation, back_above
from hrc_drake.cell.controller.follower import PlanFollower
from hrc_drake.cell.controller.guard import DescentGuard
from hrc_drake.cell.controller.intent import MotionIntent, plan_velocities
from hrc_drake.cell.controller.keep_clear import KeepClear, KeepClearSettings
from hrc_drake.cell.controller.observe import cell_shows, task_record
from hrc_drake.cell.controller.planning import PlanAsker
from hrc_drake.cell.controller.readings import Readings, SupervisorInputs
from hrc_drake.cell.controller.recovery import FaultRecovery, resolve
from hrc_drake.cell.controller.supervisor_state import (
    N_JOINTS,
    TASK_CAP,
    ArmCommand,
    Cause,
    Detection,
    Event,
    Mode,
    Recovery,
    SupervisorError,
    SupervisorLimits,
    SupervisorStatus,
    TaskInFlight,
    TaskRecord,
)
from hrc_drake.cell.ports import CellConfiguration, PartStatus, SafetyMode
from hrc_drake.hri.messages import Prompt, PromptKind
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.plan_request import PlanFailure
from hrc_drake.motion.service import PlanService
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.tokens import UNDO

# The commanded ports, each a slice of one `ArmCommand` evaluated once per plant step.
ARM_PORTS = ("ur3.position", "ur3.velocity", "rg2.opening", "rg2.force")


class Supervisor(LeafSystem):
    """Task-level state machine of the cell (see the module docstring).

    Input ports: `configuration` (CellConfiguration), `hri.indication` (Indication),
    `ur3.state_estimated` (12), `rg2.state_measured` (2: opening, rate), `rg2.grip_detected`
    (1), `speed_limit` (1: the speed scale the separation monitor allows; unconnected, 1),
    `safety.stop` (1: the robot's protective-stop input; unconnected, none), `operator.body`
    (BodySpheres, the tracked body: predictive separation holds it against its forecast;
    unconnected, nobody), `ur3.target` (6: the command the arm followed when measured, which
    the tracking check compares with; unconnected, its own), `link.stale` (1: an arm or body
    reading is stale: the plan stops on its path; unconnected, never).
    Output ports: `ur3.position` (6), `ur3.velocity` (6), `rg2.opening` (1), `rg2.force` (1),
    `hri.prompt` (Prompt), `intent` (MotionIntent), `status` (SupervisorStatus).
    `robot_limits(q, qdot, reduced)`, if given, is the speed scale at which the plan keeps
    within the UR's limit set in force (`hrc_drake.cell.robot_limits.PlanLimits`).
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
        robot_limits: Callable[[np.ndarray, np.ndarray, bool], float] | None = None,
    ):
        super().__init__()
        self._robot_limits = robot_limits
        policy.matches(space.spec)
        self._space, self._policy = space, policy
        self._limits = limits if limits is not None else SupervisorLimits()
        self._on_task = on_task
        home = tuple(float(x) for x in home)
        self._planning = PlanAsker(plans, space, policy, self._limits.plan_ahead)
        self._recovery = FaultRecovery(self._limits, space.spec, self._planning, home)
        self._anticipation = Anticipation(space, policy, self._planning)
        self._keep_clear = KeepClear(keep_clear if keep_clear is not None else KeepClearSettings())
        self._guard = DescentGuard(self._limits.guard)
        self._follower = PlanFollower(
            self._limits, self._anticipation.pause_at, self._recovery.release_wait
        )
        self._inputs = SupervisorInputs.declare(self)
        initial = follower.hold(SupervisorStatus(), home, float(home_opening))
        self._status_index = self.DeclareAbstractState(AbstractValue.Make(initial))
        self._declare_outputs()
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._limits.period, 0.0, self._update)

    def _declare_outputs(self) -> None:
        # Outputs depend on the state and time only (no feedthrough): the separation monitor
        # reads `intent` and feeds `speed_limit` back without an algebraic loop.
        deps = {self.time_ticket(), self.abstract_state_ticket(self._status_index)}
        # One command, evaluated once per plant step, read by the arm's and the gripper's ports.
        empty = ArmCommand(np.zeros(N_JOINTS), np.zeros(N_JOINTS), 0.0)
        self._command = self.DeclareCacheEntry(
            "command",
            ValueProducer(allocate=lambda: AbstractValue.Make(empty), calc=self._calc_command),
            prerequisites_of_calc=deps,
        )
        ticket = {self._command.ticket()}
        for name, size, part in (
            ("ur3.position", N_JOINTS, lambda c: c.q),
            ("ur3.velocity", N_JOINTS, lambda c: c.v),
            ("rg2.opening", 1, lambda c: [c.opening]),
        ):
            self.DeclareVectorOutputPort(
                name,
                size,
                lambda context, out, part=part: out.SetFromVector(
                    part(self._command.Eval(context))
                ),
                prerequisites_of_calc=ticket,
            )
        # The gripper always grips with the scenario's force (a real RG2 takes one with every
        # target width); the opening says whether it closes on a part. Depending on nothing,
        # it is worked out once, not at every plant step.
        force = [self._limits.grip_force]
        self.DeclareVectorOutputPort(
            "rg2.force",
            1,
            lambda context, out: out.SetFromVector(force),
            prerequisites_of_calc={self.nothing_ticket()},
        )
        for name, value, calc in (
            ("hri.prompt", Prompt(), self._calc_prompt),
            ("intent", MotionIntent(), self._calc_intent),
            ("status", SupervisorStatus(), self._calc_status),
        ):
            self.DeclareAbstractOutputPort(
                name,
                lambda value=value: AbstractValue.Make(value),
                calc,
                prerequisites_of_calc=deps,
            )

    # --- outputs -------------------------------------------------------------------------
    def _status(self, context) -> SupervisorStatus:
        return context.get_abstract_state(self._status_index).get_value()

    def _calc_command(self, context, value) -> None:
        value.set_value(self._status(context).command(context.get_time()))

    def _calc_prompt(self, context, output) -> None:
        output.set_value(self._status(context).question.prompt)

    def _calc_status(self, context, output) -> None:
        output.set_value(self._status(context))

    def _calc_intent(self, context, output) -> None:
        s = self._status(context)
        rate = s.clock.rate
        if s.mode != Mode.EXECUTE or s.plan is None:
            output.set_value(MotionIntent(rate=rate))
            return
        now = context.get_time()
        plan, tau = s.plan, s.plan_time(now)
        carrying = plan.carrying(tau)
        if s.held(now):  # a planned wait for the operator: the arm stands still
            output.set_value(MotionIntent(carrying=carrying, moving=False, rate=rate))
            return
        moving = tau < plan.duration and not s.holding_for_bolts(tau) and rate > 0
        ahead = plan_velocities(plan.trajectory, tau, plan.duration, self._limits.look_ahead)
        if tau >= plan.duration:
            ahead = np.zeros_like(ahead)
        output.set_value(
            MotionIntent(qdot=ahead[0], carrying=carrying, moving=moving, rate=rate, ahead=ahead)
        )

    # --- the state machine ---------------------------------------------------------------
    def _update(self, context, state) -> None:
        status = self._status(context)
        now = context.get_time()
        cell = Readings(self._inputs, context)
        limit = min(cell.speed_limit(), self._within_robot_limits(status, cell, now))
        stop, stale = cell.stop(), cell.stale()
        status = self._recovery.note_stop(status, stop, now, cell.safety_mode())
        if stop or stale or self._anticipation.stopping_to_turn(status, now):
            limit = 0.0  # decelerate along the path, as for the separation monitor's stop
        try:
            if not stale:  # a stale reading says nothing of where the arm is now
                self._check_tracking(status, cell, now)
            speed = float(min(max(limit, 0.0), 1.0))  # np.clip's, without its overhead
            status = self._follower.advance(status, speed, now, cell.opening())
            status = self._step(status, cell, now)
            status = self._keep_clear.update(status, cell.body, now)
        except SupervisorError as err:
            if err.hand_over:
                status = self._recovery.hand_over(status, cell, now, err)
            else:
                status = self._recovery.stop(status, cell, now, err)
        state.get_mutable_abstract_state(self._status_index).set_value(status)

    def _within_robot_limits(self, s: SupervisorStatus, cell: Readings, now: float) -> float:
        """The speed scale at which the plan keeps within the UR's limit set in force (reduced
        while the robot reports reduced mode), by the controller's own robot model; inf
        without limits or a plan under way."""
        plan = s.clock.plan
        if self._robot_limits is None or s.mode != Mode.EXECUTE or plan is None:
            return float("inf")
        tau = min(s.plan_time(now), plan.duration)
        q = plan.trajectory.value(tau).ravel()
        # As far ahead as the monitor looks: a plan that speeds up meanwhile would break them.
        ahead = plan_velocities(plan.trajectory, tau, plan.duration, self._limits.look_ahead)
        return self._robot_limits(q, ahead, cell.safety_mode() == SafetyMode.REDUCED)

    def _step(self, status: SupervisorStatus, cell: Readings, now: float) -> SupervisorStatus:
        if status.turn.awaiting and status.mode in (Mode.PLAN, Mode.BLOCKED, Mode.EXECUTE):
            status, indicated = self._indicated(status, cell, now)
            if indicated is not None:
                committed = status.turn.committed
                status = self._anticipation.on_indication(status, indicated, now)
                if indicated != committed:  # turning to it: the task in flight is it
                    status = replace(status, task=replace(status.task, indicated=indicated))
        if status.mode == Mode.EXECUTE and status.turn.change is None:
            status = self._recovery.watch_obstacle(status, cell.configuration(), now)
        if status.turn.change is not None:
            turned = self._anticipation.turn(status, cell.configuration(), now)
            if turned is not None and turned.mode != Mode.EXECUTE:
                return turned
            status = turned or status  # executing: on its way to where it turns
        return self._in_mode(status, cell, now)

    def _in_mode(self, status: SupervisorStatus, cell: Readings, now: float) -> SupervisorStatus:
        """What the Supervisor does in its mode at `now`."""
        mode = status.mode
        if mode == Mode.DECIDE:
            return self._decide(status, cell.configuration(), now)
        if mode == Mode.ASK:
            return self._take_indication(status, cell, now)
        if mode == Mode.PLAN:
            return self._take_plan(status, cell.configuration(), now)
        if mode == Mode.BLOCKED:
            return self._recovery.wait_for_path(status, cell.configuration(), now)
        if mode == Mode.EXECUTE:
            return self._execute(status, cell, now)
        if mode == Mode.SETTLE and self._settled(status, cell, now):
            return self._observe(status, cell, now)
        if mode == Mode.RECOVER and self._settled(status, cell, now):
            return self._recovery.pick_again(status, cell.configuration(), now)
        if mode == Mode.HANDOVER:
            return self._recovery.wait_for_operator(status, cell, now)
        return status

    @staticmethod
    def _settled(s: SupervisorStatus, cell: Readings, now: float) -> bool:
        """The parts have had their time to settle, and the configuration sensor's reading
        describes the cell since then (a camera's verdicts come a few frames late: the reading
        says up to when they hold, `CellConfiguration.current_at`; an exact sensor's hold now)."""
        return now >= s.settle_until and cell.configuration().current_at(s.settle_until)

    def _check_tracking(self, s: SupervisorStatus, cell: Readings, now: float) -> None:
        """Stop when a joint is farther from its command than the tolerance: the command its
        servo followed when measured (`ur3.target`, RTDE's `target_q`), else the last."""
        if s.mode in (Mode.DONE, Mode.FAILED):
            return
        q = cell.arm_q()
        target = cell.arm_target()
        error = np.abs(q - (s.command(now).q if target is None else target))
        worst = int(np.argmax(error))
        if error[worst] > self._limits.tracking_tolerance:
            raise SupervisorError(
                f"step {s.step}: {UR3_JOINTS[worst]} is {error[worst]:.3f} rad from its command "
                f"(tolerance {self._limits.tracking_tolerance} rad): the arm is pushed or "
                "blocked; the task is stopped and the arm holds where it is",
                cause=Cause.TRACKING,
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
            return s.noted(f"{now:.2f}: done").enter(Event.FINISHED)
        if s.step >= self._limits.max_steps:
            raise SupervisorError(
                f"no terminal state after {s.step} tasks (the run's cap, run.max_steps)",
                cause=TASK_CAP,
            )
        if s.step == 0:
            self._planning.plan_ahead_of(s.state, config.layout())
        proposal = self._policy.next_task(s.state)
        anticipate = self._limits.anticipate
        committed = self._anticipation.commit(s.state, proposal) if anticipate else None
        prompt = Prompt(s.step + 1, PromptKind.CHOOSE, s.state, proposal, committed=committed or "")
        s = question.asked(s.enter(Event.PROPOSED), prompt, now)
        s = anticipation.committed_to(replace(s, step=s.step + 1, tokens_before=tokens), committed)
        if committed is None:
            return s
        event = f"{now:.2f}: step {s.step} proposes {proposal}, starts on {committed}"
        s = replace(s.noted(event), task=TaskInFlight(proposal, committed))
        return self._planning.ask_task(s, committed, config, now)

    def _indicated(self, s: SupervisorStatus, cell: Readings, now: float):
        """(status, the task the operator indicated, checked feasible) once the answer to the
        prompt is in; (status noting any silence, None) before."""
        indication = cell.indication()
        if not indication.answers(s.question.prompt):
            return self._recovery.note_silence(s, now), None
        s = resolve(s, Cause.SILENCE, now, Recovery.ASK)
        return s, self._feasible(s, indication.task)

    def _take_indication(self, s: SupervisorStatus, cell: Readings, now: float):
        """Once the operator indicates a task: check it, then ask the planner for it."""
        s, indicated = self._indicated(s, cell, now)
        if indicated is None:
            return s
        proposal = s.question.prompt.proposal
        event = f"{now:.2f}: step {s.step} proposes {proposal}, operator indicates "
        s = question.answered(s.noted(event + indicated), now)
        s = replace(s, task=TaskInFlight(proposal, indicated))
        return self._planning.ask_task(s, indicated, cell.configuration(), now)

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
        request = s.ask.request
        result = self._planning.plans.poll(request)
        if result is None:
            return s
        step, indicated = s.step, s.task.indicated
        recovering = s.recovery.recovering
        if isinstance(result, PlanFailure) and request.obstacle is not None:
            return self._recovery.blocked(s, result, now)
        if isinstance(result, PlanFailure) and recovering:
            raise SupervisorError(
                f"step {step}: the robot cannot pick {s.task.part} from where it lies "
                f"({result.reason}); the task is handed over",
                cause=Cause.PLAN,
                hand_over=True,
            )
        if isinstance(result, PlanFailure):
            return self._no_plan(s, result, now)
        plan: Plan = result
        s = resolve(s, Cause.PLAN, now, Recovery.RETRY)  # a path once the obstacle moved
        placement = config.placement(plan.instance)
        expected = PartStatus.SEATED if indicated == UNDO else PartStatus.TRAY
        if placement.status != expected and not (recovering or request.held):
            raise SupervisorError(
                f"step {step}: {plan.instance} should be {expected.value} for {indicated}, the "
                f"cell shows it {placement.status.value}"
            )
        started = replace(
            follower.start(s.enter(Event.PLAN_STARTED), plan, now),
            task=replace(s.task, part=plan.instance),
            bolted=False,
            planned_ahead=s.turn.returning,  # a part put back: nothing to plan ahead for yet
        )
        started = anticipation.plan_started(recovery.plan_started(started), plan)
        started = planning.plan_taken(started, now)
        if started.turn.awaiting and plan.task == started.turn.committed:
            return self._anticipation.plan_retargets(started, config)
        return started

    def _no_plan(self, s: SupervisorStatus, failure: PlanFailure, now: float):
        """No plan for the task (no IK, a collision, the solver failed), no obstacle to wait
        out: the robot is sound, the task is not its own. Committed before the indication, it
        drops the commitment and waits for the indication (as in `wait` mode); carrying a
        part to another seat, it puts the part back in its tray first (then plans the
        indicated task from there, and hands it over if that fails too); else the task is
        handed over (`FaultRecovery.hand_over`) and the assembly goes on. A part it cannot put
        back stops the run."""
        request = s.ask.request
        if s.turn.awaiting and not request.held:
            event = f"{now:.2f}: step {s.step}: cannot start on {request.task} ({failure.reason})"
            s = s.noted(f"{event}; waits for the indication").enter(Event.NO_START)
            # No longer on its way to the task it committed to.
            return anticipation.dropped(question.uncommitted(replace(s, task=None)))
        if request.held and request.task != UNDO:
            event = f"{now:.2f}: {failure}: puts {request.instance} back first"
            s = anticipation.putting_back(s.noted(event))
            return self._planning.ask(s, replace(request, task=UNDO), now)
        if request.held:  # the way back to the tray: the part is in the gripper
            raise SupervisorError(f"step {s.step}: {failure}", cause=Cause.PLAN)
        raise SupervisorError(
            f"step {s.step}: {failure}; the task is handed over", cause=Cause.PLAN, hand_over=True
        )

    def _execute(self, s: SupervisorStatus, cell: Readings, now: float):
        """Follow the plan: check the grasp, prompt for the bolts and wait for them, plan the
        next task ahead, and settle at the end."""
        plan = s.plan
        tau = s.plan_time(now)
        s = self._recovery.check_grip(s, cell, now)
        if s.mode != Mode.EXECUTE:
            return s  # the part was lost: it is picked again once it rests
        if self._guard.in_descent(plan, tau) and not s.turn.returning:
            guard, trip = self._guard.watch(
                s.guard, plan, s.clock.plan_start, tau, cell.arm_q(), cell.wrench()
            )
            s = replace(s, guard=guard)
            if trip is not None:  # the part met something before its seat
                return self._recovery.stop_pressing(s, trip, now)
        if tau >= plan.t_in_place and not s.planned_ahead:
            s = replace(s, planned_ahead=True)
            self._planning.plan_ahead_after(s, cell.configuration())
        if s.holding_for_bolts(tau):
            return self._hold_for_bolts(s, cell, now)
        above = back_above(plan) if s.turn.returning else None
        if above is not None and tau >= above:  # the part is back: the indicated task
            q = tuple(float(x) for x in plan.trajectory.value(above).ravel())
            s = anticipation.put_back(follower.hold(s, q, plan.gripper_opening(above)))
            config = cell.configuration()
            return self._planning.ask_task(s, s.task.indicated, config, now, start=q)
        if tau >= plan.duration:
            q_end = tuple(float(x) for x in plan.trajectory.value(plan.duration).ravel())
            s = s.enter(Event.PLAN_DONE, now + self._limits.settle_time)
            return question.cleared(follower.hold(s, q_end, plan.gripper_opening(plan.duration)))
        return s

    def _hold_for_bolts(self, s: SupervisorStatus, cell: Readings, now: float):
        """Hold the part in place: prompt BOLT once; on `bolted`, go on to the release."""
        indicated, part = s.task.indicated, s.task.part
        if s.question.prompt.kind != PromptKind.BOLT:
            prompt = Prompt(s.step, PromptKind.BOLT, s.state, indicated, part)
            return question.holding(s.noted(f"{now:.2f}: holds {part}"), prompt, now)
        if not cell.indication().answers(s.question.prompt):
            return s
        s = s.noted(f"{now:.2f}: operator has bolted {part}")
        return follower.to_release(replace(s, bolted=True), now)

    def _observe(self, s: SupervisorStatus, cell: Readings, now: float):
        """After the task: what the cell shows was done moves the MDP state on. A part let go
        out of any seat is picked again and re-placed (up to `recover_tries` times); then, or
        when the robot cannot pick it, the task is handed over. A task the operator did by
        hand is read the same way (and never handed over again)."""
        indicated, part = s.task.indicated, s.task.part
        config: CellConfiguration = cell.configuration()
        handover, guarded = s.recovery.handover, s.recovery.guarded
        s = follower.backed_off(recovery.settled(s))
        # A part the guarded descent let go early is placed again even if it fell into its
        # seat: it was never held there for the bolts.
        unseated = (
            indicated != UNDO
            and not handover
            and (
                guarded
                or config.placement(part).status in (PartStatus.MISPLACED, PartStatus.TRANSIT)
            )
        )
        if unseated and s.recovery.recoveries < self._limits.recover_tries:
            return self._recovery.lose_part(s, cell, now, Cause.SEAT, Recovery.REPLACE)
        observed, next_state = cell_shows(s, config, self._space)
        if handover and not part:  # handed over before the robot chose a part
            part = next((i for i, t in config.layout().items() if t == observed), "")
        recovering = s.recovery.recovering
        if recovering:
            for cause in (Cause.GRIP, Cause.SEAT):
                s = resolve(s, cause, now, recovering)
        record = task_record(s, observed, next_state, part, now)
        if self._on_task is not None:
            self._on_task(record)
        event = f"{now:.2f}: cell shows {observed}; state {' '.join(next_state) or '(start)'}"
        s = planning.task_closed(recovery.task_closed(s.noted(event).enter(Event.TASK_READ)))
        return replace(s, state=next_state, task=None, history=(*s.history, record))


__all__ = [
    "ARM_PORTS",
    "Detection",
    "Mode",
    "Supervisor",
    "SupervisorError",
    "SupervisorLimits",
    "SupervisorStatus",
    "TaskRecord",
]
