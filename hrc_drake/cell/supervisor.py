"""The Supervisor: at every task boundary it reads the cell, asks the policy, and drives the robot.

At a task boundary the Supervisor
1. reads the SlotMonitor's configuration and, with the history it has seen, the MDP state;
2. asks the Policy for the next task and proposes it on the HRI;
3. takes the operator's answer (confirm, or another task: the slot the operator indicates);
4. asks the motion layer for the plan and drives the UR3 and the gripper through it: pick,
   carry, place, hold while the operator bolts, release, retreat (or, for `undo`, take the part
   placed last back to the tray);
5. after the task, learns what really happened from the SlotMonitor — the part may sit in
   another seat than planned — and only then moves the MDP state on.

The robot follows its plan in plan time `tau`, which advances at the speed scale s ∈ [0, 1] that
the separation monitor (`hrc_drake.cell.safety`) allows on the optional `speed_limit` input: the
robot slows down by scaling its trajectory's time, stops with s = 0 and resumes as s ramps back,
never faster than the arm's joint acceleration limit allows. While the plan holds the part still
for bolting, `tau` runs with simulated time whatever s is (a monitored stop); at the end of
the hold the robot moves on only when s > 0. All stage logic (grasp and bolt welds, release)
reads `tau`.

Grasping and bolting are weld constraints of the plant. A Drake system cannot write another
system's parameters from its events, so the Supervisor publishes the welds it wants on its
`welds` port; the simulator's monitor (`hrc_drake.cell.run`) stops the simulation at the step
where they change, applies them, and goes on.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.slot_monitor import CellConfiguration, PartStatus
from hrc_drake.motion.plan import Plan, Stage
from hrc_drake.tasks.decide import Operator
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.tokens import UNDO

# (configuration, task, last token, measured layout: instance -> token) -> Plan
Planner = Callable[[frozenset[str], str, str | None, dict[str, str]], Plan]


class Mode(enum.Enum):
    """What the Supervisor is doing."""

    DECIDE = "decide"  # at a task boundary
    EXECUTE = "execute"  # following a plan
    SETTLE = "settle"  # plan done; let the parts come to rest before reading the cell
    DONE = "done"  # a terminal state is reached
    FAILED = "failed"  # cannot go on (the reason is in `error`)


@dataclass(frozen=True)
class TaskRecord:
    """One task as it happened."""

    step: int
    state: tuple[str, ...]
    proposed: str
    indicated: str  # the task the operator confirmed or indicated instead
    observed: str  # the task the cell shows was done (from contact), or "undo"
    next_state: tuple[str, ...]
    part: str
    start_time: float
    end_time: float


@dataclass(frozen=True)
class Weld:
    """A weld constraint the Supervisor wants active: a grasp, or a bolt at a seat."""

    kind: str  # "grasp" | "bolt"
    part: str
    seat: str = ""  # bolt: the seat key (token on the plate, "<host>/row_<j>" on a host part)


@dataclass(frozen=True)
class SupervisorStatus:
    """The Supervisor's abstract state (one value, replaced at every update)."""

    mode: Mode = Mode.DECIDE
    state: tuple[str, ...] = ()
    step: int = 0
    plan: Plan | None = None
    plan_start: float = 0.0
    pending: tuple[str, str, str] | None = None  # (proposed, indicated, part) of the task
    tokens_before: frozenset[str] = frozenset()
    settle_until: float = 0.0
    welds: frozenset[Weld] = frozenset()
    bolt_seat: str | None = None
    q_hold: tuple[float, ...] = ()
    opening_hold: float = 0.0
    history: tuple[TaskRecord, ...] = ()
    error: str | None = None
    events: tuple[str, ...] = field(default_factory=tuple)
    tau: float = 0.0  # plan time at `tau_time` (simulated time)
    tau_time: float = 0.0
    rate: float = 1.0  # d tau / dt from `tau_time` on
    speed: float = 1.0  # the speed scale s the robot runs at (1: the plan's own speed)

    def __deepcopy__(self, memo) -> SupervisorStatus:
        # Drake copies abstract values at every update and output evaluation; this value is
        # immutable (its plan's trajectories are never modified), so the copy is itself.
        return self

    def plan_time(self, now: float) -> float:
        """The plan time `tau` at simulated time `now` (clamped to the plan)."""
        tau = self.tau + self.rate * (now - self.tau_time)
        return float(np.clip(tau, 0.0, self.plan.duration)) if self.plan is not None else tau

    @property
    def visited(self) -> list[tuple[str, ...]]:
        """The MDP states visited, from the start."""
        return [(), *(r.next_state for r in self.history)]


class Supervisor(LeafSystem):
    """Task-level state machine of the cell (see the module docstring).

    Input ports: `slot_configuration` (CellConfiguration), `speed_limit` (1: the speed scale the
    separation monitor allows; unconnected, 1). Output ports: `ur3.desired_state`
    (12), `rg2.desired_opening` (1), `welds` (frozenset[Weld]), `status` (SupervisorStatus).
    `policy` needs `next_task(state)` and `matches(spec)` (a `Policy`, or a decider wrapped by
    `hrc_drake.cell.evaluate.DeciderPolicy`); `on_task(record)`, if given, hears every task as
    the cell observed it (a learning decider updates its operator model from it).
    """

    def __init__(
        self,
        space: StateSpace,
        policy: Policy,
        operator: Operator,
        planner: Planner,
        home: np.ndarray,
        home_opening: float,
        period: float = 0.02,
        settle_time: float = 0.3,
        max_steps: int = 30,
        joint_acceleration: float = 5.0,
        on_task: Callable[[TaskRecord], None] | None = None,
    ):
        super().__init__()
        policy.matches(space.spec)
        self._space, self._policy, self._operator, self._planner = space, policy, operator, planner
        self._on_task = on_task
        self._settle_time, self._max_steps = settle_time, max_steps
        self._period, self._joint_acceleration = period, joint_acceleration
        self._config_port = self.DeclareAbstractInputPort(
            "slot_configuration", AbstractValue.Make(CellConfiguration())
        )
        initial = SupervisorStatus(
            q_hold=tuple(float(x) for x in home), opening_hold=float(home_opening)
        )
        self._speed_port = self.DeclareVectorInputPort("speed_limit", BasicVector(1))
        self._status_index = self.DeclareAbstractState(AbstractValue.Make(initial))
        # Outputs depend on the state and time only (no feedthrough): the separation monitor
        # reads `status` and feeds `speed_limit` back without an algebraic loop.
        deps = {self.time_ticket(), self.abstract_state_ticket(self._status_index)}
        self.DeclareVectorOutputPort(
            "ur3.desired_state", BasicVector(12), self._calc_arm, prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "rg2.desired_opening", BasicVector(1), self._calc_gripper, prerequisites_of_calc=deps
        )
        self.DeclareAbstractOutputPort(
            "welds",
            lambda: AbstractValue.Make(frozenset()),
            self._calc_welds,
            prerequisites_of_calc=deps,
        )
        self.DeclareAbstractOutputPort(
            "status",
            lambda: AbstractValue.Make(SupervisorStatus()),
            self._calc_status,
            prerequisites_of_calc=deps,
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    # --- outputs -------------------------------------------------------------------------
    def _status(self, context) -> SupervisorStatus:
        return context.get_abstract_state(self._status_index).get_value()

    def _calc_arm(self, context, output) -> None:
        s = self._status(context)
        if s.mode == Mode.EXECUTE and s.plan is not None:
            tau = s.plan_time(context.get_time())
            q = s.plan.trajectory.value(tau).ravel()
            v = s.plan.trajectory.EvalDerivative(tau, 1).ravel() * s.rate
            if tau >= s.plan.duration:
                v = np.zeros_like(v)
            output.SetFromVector(np.concatenate([q, v]))
        else:
            output.SetFromVector(np.concatenate([s.q_hold, np.zeros(len(s.q_hold))]))

    def _calc_gripper(self, context, output) -> None:
        s = self._status(context)
        if s.mode == Mode.EXECUTE and s.plan is not None:
            output.SetFromVector([s.plan.gripper_opening(s.plan_time(context.get_time()))])
        else:
            output.SetFromVector([s.opening_hold])

    def _calc_welds(self, context, output) -> None:
        output.set_value(self._status(context).welds)

    def _calc_status(self, context, output) -> None:
        output.set_value(self._status(context))

    # --- the state machine ---------------------------------------------------------------
    def _update(self, context, state) -> None:
        status = self._status(context)
        config = self._config_port.Eval(context)
        now = context.get_time()
        limit = self._speed_port.Eval(context)[0] if self._speed_port.HasValue(context) else 1.0
        try:
            status = self._advance(status, float(np.clip(limit, 0.0, 1.0)), now)
            if status.mode == Mode.DECIDE:
                status = self._decide(status, config, now)
            elif status.mode == Mode.EXECUTE:
                status = self._execute(status, config, now)
            elif status.mode == Mode.SETTLE and now >= status.settle_until:
                status = self._observe(status, config, now)
        except SupervisorError as err:
            status = replace(status, mode=Mode.FAILED, error=str(err), plan=None)
        state.get_mutable_abstract_state(self._status_index).set_value(status)

    def _advance(self, s: SupervisorStatus, limit: float, now: float) -> SupervisorStatus:
        """Move the plan time to `now`, then ramp the speed scale toward `limit` (no faster
        than the joint acceleration limit allows at the plan's speed) and set the rate on."""
        if s.mode != Mode.EXECUTE or s.plan is None:
            return replace(s, speed=limit)
        plan = s.plan
        tau = s.plan_time(now)
        qdot = np.abs(plan.trajectory.EvalDerivative(min(tau, plan.duration), 1)).max()
        step = self._joint_acceleration * self._period / max(qdot, 1e-9)
        speed = float(np.clip(limit, s.speed - step, s.speed + step))
        hold = next((g for g in plan.segments if g.stage == Stage.HOLD), None)
        # The hold is a monitored stop: the arm stands still, its time runs on.
        holding = hold is not None and hold.start <= tau and tau + self._period <= hold.end
        return replace(s, tau=tau, tau_time=now, speed=speed, rate=1.0 if holding else speed)

    def _decide(self, s: SupervisorStatus, config: CellConfiguration, now: float):
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
        if s.step >= self._max_steps:
            raise SupervisorError(f"no terminal state after {s.step} tasks")
        step = s.step + 1
        proposed = self._policy.next_task(s.state)
        indicated = self._operator(step, s.state, proposed)
        feasible = {t for t, _ in space.tasks(index)}
        if indicated not in feasible:
            raise SupervisorError(
                f"step {step}: the operator indicated {indicated!r}, not feasible in "
                f"{list(s.state)} (feasible: {sorted(feasible)})"
            )
        last = s.state[-1] if s.state else None
        try:
            plan = self._planner(tokens, indicated, last, config.layout())
        except (RuntimeError, ValueError) as err:  # UnreachableError, PlanningError, bad input
            raise SupervisorError(
                f"step {step}: no plan for {indicated} from {sorted(tokens)}: {err}"
            ) from err
        placement = config.placement(plan.instance)
        expected = PartStatus.SEATED if indicated == UNDO else PartStatus.TRAY
        if placement.status != expected:
            raise SupervisorError(
                f"step {step}: {plan.instance} should be {expected.value} for {indicated}, the "
                f"cell shows it {placement.status.value}"
            )
        event = f"{now:.2f}: step {step} proposes {proposed}, operator indicates {indicated}"
        return replace(
            s,
            mode=Mode.EXECUTE,
            step=step,
            plan=plan,
            plan_start=now,
            tau=0.0,
            tau_time=now,
            rate=s.speed,
            pending=(proposed, indicated, plan.instance),
            tokens_before=tokens,
            bolt_seat=None,
            events=(*s.events, event),
        )

    def _execute(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        plan = s.plan
        tau = s.plan_time(now)
        part = plan.instance
        grasp, welds = Weld("grasp", part), set(s.welds)
        grasped_at = plan.segment(Stage.GRASP).end
        bolt_seat = s.bolt_seat
        if grasped_at <= tau < plan.t_release:
            welds.add(grasp)
            # Taking a part back: unbolt it once it is held.
            welds -= {w for w in welds if w.kind == "bolt" and w.part == part}
        if tau >= plan.t_release:
            welds.discard(grasp)
            if plan.task != UNDO and bolt_seat is None:
                # The operator has bolted the part where it really sits (read from contact).
                placement = config.placement(part)
                if placement.status == PartStatus.SEATED and placement.seats:
                    bolt_seat = (
                        placement.token
                        if placement.host is None
                        else f"{placement.host}/{placement.seats[0]}"
                    )
                    welds.add(Weld("bolt", part, bolt_seat))
                else:
                    bolt_seat = ""
        s = replace(s, welds=frozenset(welds), bolt_seat=bolt_seat)
        if tau >= plan.duration:
            q_end = tuple(float(x) for x in plan.trajectory.value(plan.duration).ravel())
            return replace(
                s,
                mode=Mode.SETTLE,
                settle_until=now + self._settle_time,
                q_hold=q_end,
                opening_hold=plan.gripper_opening(plan.duration),
                plan=None,
            )
        return s

    def _observe(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        space = self._space
        proposed, indicated, part = s.pending
        tokens = config.tokens()
        added, removed = tokens - s.tokens_before, s.tokens_before - tokens
        if indicated == UNDO:
            if added or removed != {s.state[-1]}:
                raise SupervisorError(
                    f"after undo of {s.state[-1]} the cell shows {sorted(tokens)} (removed "
                    f"{sorted(removed)}, added {sorted(added)})"
                )
            observed, next_state = UNDO, s.state[:-1]
        else:
            if removed or len(added) != 1:
                raise SupervisorError(
                    f"after {indicated} the cell shows {sorted(tokens)}: {part} is "
                    f"{config.placement(part).status.value}, not in a seat"
                )
            (observed,) = added
            next_state = (*s.state, observed)
            if observed not in {t for t, _ in space.tasks(space.index(s.state))}:
                raise SupervisorError(
                    f"the cell shows {observed} placed, not a feasible task from {list(s.state)}"
                )
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
        )
        if self._on_task is not None:
            self._on_task(record)
        event = f"{now:.2f}: cell shows {observed}; state {' '.join(next_state) or '(start)'}"
        return replace(
            s,
            mode=Mode.DECIDE,
            state=next_state,
            pending=None,
            history=(*s.history, record),
            events=(*s.events, event),
        )


class SupervisorError(RuntimeError):
    """The supervisor cannot go on."""
