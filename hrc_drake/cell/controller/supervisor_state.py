"""The Supervisor's values: its mode, its abstract state, what it records and its limits (no
Drake systems; `hrc_drake.cell.controller.supervisor` runs them)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np

from hrc_drake.cell.controller.forecast import Anchor
from hrc_drake.cell.controller.guard import GuardSettings, GuardState, Retreat
from hrc_drake.cell.controller.separation import MONITOR_LAG
from hrc_drake.hri.messages import Prompt
from hrc_drake.motion.clearance import Hold
from hrc_drake.motion.path_time import SpeedCap
from hrc_drake.motion.plan import Plan
from hrc_drake.motion.plan_request import PlanRequest
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.tasks.tokens import UNDO

N_JOINTS = len(UR3_JOINTS)
# After the fingers close, this long for them to stall on the part before the grasp is checked;
# and a grasp that looks lost must stay so this long (a jolt of the carry is not a loss).
GRIP_SETTLE = 0.1  # s
# A part that slips out of the fingers falls at most about 0.3 m (0.25 s) and rattles to rest.
PART_FALL_TIME = 1.0  # s


class Mode(enum.Enum):
    """What the Supervisor is doing."""

    DECIDE = "decide"  # at a task boundary
    ASK = "ask"  # the proposal is shown; waiting for the operator's indication
    PLAN = "plan"  # waiting for the planner (the arm holds still)
    BLOCKED = "blocked"  # no path past an obstacle: waiting for it to move or go
    EXECUTE = "execute"  # following a plan (holding the part while the operator bolts it)
    SETTLE = "settle"  # plan done; let the parts come to rest before reading the cell
    RECOVER = "recover"  # a part lost or not seated: it comes to rest, then is picked again
    HANDOVER = "handover"  # the task is the operator's: the arm holds still until it is done
    DONE = "done"  # a terminal state is reached
    FAILED = "failed"  # cannot go on (the reason is in `error`)


class Event(enum.StrEnum):
    """What moves the Supervisor from one mode to the next (`TRANSITIONS`)."""

    PROPOSED = "proposed"  # the policy's proposal is on the interface
    FINISHED = "finished"  # the cell shows a terminal state
    PLAN_ASKED = "plan-asked"  # a plan is asked for; the arm holds still until it comes
    NO_START = "no-start"  # no plan for the commitment: the indication is waited for
    PLAN_STARTED = "plan-started"  # the plan came: the arm follows it
    PATH_BLOCKED = "path-blocked"  # no path past an obstacle
    PLAN_DONE = "plan-done"  # the plan's end: the parts settle
    GUARD_TRIPPED = "guard-tripped"  # the guarded descent let the part go early
    PART_LOST = "part-lost"  # a part out of the gripper or its seat
    HANDED_OVER = "handed-over"  # the operator is asked to do the task by hand
    DONE_BY_HAND = "done-by-hand"  # the operator did the handed-over task
    TASK_READ = "task-read"  # the cell was read after the task: the next boundary
    STOPPED = "stopped"  # the run stops


_WORKING = (Mode.ASK, Mode.PLAN, Mode.BLOCKED, Mode.EXECUTE, Mode.SETTLE, Mode.RECOVER)
# Every mode change of the Supervisor: {(mode, event): next mode}. A pair not listed is a bug
# (`transition` refuses it); a run may stop (`Event.STOPPED`) in any mode.
TRANSITIONS: dict[tuple[Mode, Event], Mode] = {
    (Mode.DECIDE, Event.PROPOSED): Mode.ASK,
    (Mode.DECIDE, Event.FINISHED): Mode.DONE,
    **{
        (mode, Event.PLAN_ASKED): Mode.PLAN
        for mode in (Mode.DECIDE, Mode.ASK, Mode.PLAN, Mode.BLOCKED, Mode.EXECUTE, Mode.RECOVER)
    },
    (Mode.PLAN, Event.NO_START): Mode.ASK,
    (Mode.PLAN, Event.PLAN_STARTED): Mode.EXECUTE,
    (Mode.PLAN, Event.PATH_BLOCKED): Mode.BLOCKED,
    (Mode.EXECUTE, Event.PLAN_DONE): Mode.SETTLE,
    (Mode.EXECUTE, Event.GUARD_TRIPPED): Mode.SETTLE,
    (Mode.EXECUTE, Event.PART_LOST): Mode.RECOVER,
    (Mode.SETTLE, Event.PART_LOST): Mode.RECOVER,
    **{(mode, Event.HANDED_OVER): Mode.HANDOVER for mode in _WORKING},
    (Mode.HANDOVER, Event.DONE_BY_HAND): Mode.SETTLE,
    (Mode.SETTLE, Event.TASK_READ): Mode.DECIDE,
    **{(mode, Event.STOPPED): Mode.FAILED for mode in Mode},
}


class TransitionError(RuntimeError):
    """A mode change that `TRANSITIONS` does not list (a bug in the Supervisor, never a fault
    of the cell: it is not caught as a `SupervisorError` is)."""


def transition(mode: Mode, event: Event) -> Mode:
    """The mode after `event` in `mode`; TransitionError if `TRANSITIONS` does not list it."""
    try:
        return TRANSITIONS[(mode, event)]
    except KeyError:
        raise TransitionError(
            f"no transition from mode {mode.value!r} on event {event.value!r}: list it in "
            "supervisor_state.TRANSITIONS if it is meant"
        ) from None


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
    # Simulated seconds the arm held still for the planner after its last request; while
    # simulated time stands still for the planner that is one update, and the machine's own
    # planning time is `wall_idle` (wall-clock seconds, not reproducible from run to run).
    idle: float = 0.0
    wall_idle: float = 0.0
    plan_ready: bool = False  # the plan was made ahead of the indication
    committed: str | None = None  # the task the robot started on before the indication
    indicated_at: float | None = None  # when the indication came [s]
    held_at: float | None = None  # when the part was in place, held for the bolts [s]
    retargeted: bool = False  # the robot turned to another seat for the same kind of part
    swapped: bool = False  # the robot turned to another part (putting a carried one back)
    handed_over: str = ""  # why the operator did the task by hand ("": the robot did it)


class Cause(enum.StrEnum):
    """What the Supervisor found wrong, from its measurements (a `Detection`'s cause)."""

    STOP = "stop"  # the protective-stop input
    SILENCE = "silence"  # no indication within the timeout
    TRACKING = "tracking"  # a joint off its command
    GRIP = "grip"  # the fingers do not hold the part
    RELEASE = "release"  # the fingers do not open
    SEAT = "seat"  # a part let go does not sit in its seat
    PLAN = "plan"  # no plan
    CONFIGURATION = "configuration"  # the cell shows what no task explains
    TASK_CAP = "task-cap"  # the run's own task cap (`run.max_steps`): no fault


class Recovery(enum.StrEnum):
    """How a `Detection` was resolved, or how the task's part is being picked again."""

    RESUME = "resume"  # the stop cleared: the robot goes on where it stopped
    ASK = "ask"  # asked again: the indication came
    REGRASP = "regrasp"  # a part slipped out of the fingers, picked again where it lies
    REPLACE = "replace"  # a part let go out of its seat, picked again and re-placed
    RETRY = "retry"  # planned again once the obstacle moved
    OPERATOR = "operator"  # handed over: the operator did the task (or the run stopped)


@dataclass(frozen=True)
class Detection:
    """Something the Supervisor found wrong from its measurements, and what came of it.

    `resolved_at` is when the cell went on (for `Recovery.OPERATOR`: when the operator said
    the handed-over task is done, or when the run stopped)."""

    cause: Cause
    step: int
    at: float
    resolved_at: float | None = None
    recovery: Recovery | None = None

    @property
    def recovered(self) -> bool:
        """The cell itself recovered and went on."""
        return self.resolved_at is not None and self.recovery != Recovery.OPERATOR


@dataclass(frozen=True)
class TaskInFlight:
    """The task under way between the indication and the cell's reading of it."""

    proposed: str  # the policy's proposal
    indicated: str  # the task the operator indicated (or the robot committed to)
    part: str = ""  # the part instance its plan moves ("": not chosen yet)


@dataclass(frozen=True)
class PlanAsk:
    """The planner's request in flight, and what its wait cost the current task."""

    request: PlanRequest | None = None
    requested_at: float = 0.0  # simulated time when the plan was asked for
    requested_wall: float = 0.0  # perf_counter() when the plan was asked for
    plan_ready: bool = False  # the plan was made ahead of the indication
    idle: float = 0.0  # simulated seconds waited on the planner for the current task
    wall_idle: float = 0.0  # the same wait in wall-clock seconds


@dataclass(frozen=True)
class Question:
    """The operator's interface: the prompt up and when the operator was asked and answered."""

    prompt: Prompt = field(default_factory=Prompt)
    asked_at: float = 0.0  # when the operator was last asked to choose
    prompted_at: float = 0.0  # when the question now up was first asked (for the give-up)
    indicated_at: float | None = None  # when the indication came
    held_at: float | None = None  # when the robot last held the part for the bolts


@dataclass(frozen=True)
class HeldWait:
    """A planned wait the arm stands in: at plan time `tau`, since simulated time `since`."""

    tau: float
    since: float


@dataclass(frozen=True)
class PlanClock:
    """The plan the robot follows and its plan time `tau`, which advances at `rate`."""

    plan: Plan | None = None
    plan_start: float = 0.0  # simulated time the plan started
    tau: float = 0.0  # plan time at `tau_time` (simulated time)
    tau_time: float = 0.0
    rate: float = 1.0  # d tau / dt from `tau_time` on
    speed: float = 1.0  # the speed scale s the robot runs at (1: the plan's own speed)
    # Predictive separation's waits for the operator (rest points of the plan and until when),
    # the one the arm stands in, and the seconds spent in them.
    holds: tuple[Hold, ...] = ()
    held_since: HeldWait | None = None
    waited: float = 0.0
    # With `safety.timing: path_time`, the speed the arm keeps under along its timed motions
    # (the monitor's limit still applies beneath it).
    caps: tuple[SpeedCap, ...] = ()

    def hold_at(self, now: float) -> Hold | None:
        """The planned wait the arm is in, or comes to, at `now` (None: none ahead)."""
        for hold in self.holds:
            if now < hold.until and self.tau <= hold.tau + 1e-9:
                return hold
        return None


@dataclass(frozen=True)
class TurnState:
    """Anticipation (`hrc_drake.cell.controller.anticipation`): the task the robot started on
    before the indication, and its turn to the task indicated instead."""

    committed: str | None = None  # the task the robot started on
    awaiting: bool = False  # started on `committed`; the indication is not in yet
    change: str | None = None  # the indicated task the robot is stopping to turn to
    # Re-targeting on the way: the plan time of the rest point of the plan (the lift's end, the
    # pre-place pose) where the arm turns to `turn_request`, asked for while it goes there.
    turn_tau: float | None = None
    turn_request: PlanRequest | None = None
    retargets_ahead: frozenset = frozenset()  # the keys of the re-targets asked ahead
    retargeted: bool = False
    swapped: bool = False
    returning: bool = False  # carrying the committed part back to its tray (a swap)


@dataclass(frozen=True)
class KeepClearState:
    """Predictive separation (`hrc_drake.cell.controller.keep_clear`): what the plan's waits
    were timed for and what the tracker showed of the operator's activity."""

    clear_key: tuple = ()
    timed_at: float = float("-inf")  # when the plan was last timed around the forecast
    seen: Anchor | None = None  # the activity as the tracker showed it (None: as forecast)
    visiting: int | None = None  # the stay of the activity the hand is seen at
    checked_at: float = float("-inf")  # when the tracked body was last held against it
    replans: int = 0  # re-timed because the body departed from the forecast
    slips: int = 0  # re-timed because the arm fell off its path timing (`path_time`)
    forecast_view: tuple[tuple[float, float, float], ...] = ()  # forecast hand, for drawing


@dataclass(frozen=True)
class RecoveryState:
    """Fault handling (`hrc_drake.cell.controller.recovery`): a part being picked again, a grasp
    that looks lost, a blocked path, a stop, a task handed over."""

    recovering: Recovery | None = None  # REGRASP or REPLACE while the part is picked again
    recoveries: int = 0  # how often the task's part was picked again
    grip_lost_at: float | None = None  # when the grasp (or the release) started to look wrong
    blocked_at: float = 0.0  # when the task's path was found blocked
    stopped: bool = False  # the protective-stop input is on
    handover: str = ""  # why the task is handed over to the operator ("": it is not)
    away: bool = False  # the arm holds away from home: the next plan starts where it holds
    guarded: bool = False  # the guarded descent stopped the place: the part was let go early


@dataclass(frozen=True)
class SupervisorStatus:
    """The Supervisor's abstract state (one value, replaced at every update): its mode and
    MDP state, the task in flight, the records of its parts, and what the run recorded."""

    mode: Mode = Mode.DECIDE
    state: tuple[str, ...] = ()
    step: int = 0
    task: TaskInFlight | None = None
    tokens_before: frozenset[str] = frozenset()  # the cell's tokens at the task's boundary
    settle_until: float = 0.0
    bolted: bool = False
    planned_ahead: bool = False
    # Where the arm holds when it follows no plan, and the gripper's opening there.
    q_hold: tuple[float, ...] = ()
    opening_hold: float = 0.0
    ask: PlanAsk = PlanAsk()
    question: Question = Question()
    clock: PlanClock = PlanClock()
    turn: TurnState = TurnState()
    clear: KeepClearState = KeepClearState()
    recovery: RecoveryState = RecoveryState()
    guard: GuardState = field(default_factory=GuardState)
    # After a guarded stop, settling: the arm backs off up its descent (else it holds `q_hold`).
    retreat: Retreat | None = None
    history: tuple[TaskRecord, ...] = ()
    detections: tuple[Detection, ...] = ()
    events: tuple[str, ...] = ()
    error: str | None = None
    capped: bool = False  # ended by its own task cap (`run.max_steps`), not by a failure

    def __deepcopy__(self, memo) -> SupervisorStatus:
        # Drake copies abstract values at every update and output evaluation; this value is
        # immutable (its plan's trajectories are never modified), so the copy is itself.
        return self

    @property
    def plan(self) -> Plan | None:
        """The plan the robot follows (None: it holds still)."""
        return self.clock.plan

    def plan_time(self, now: float) -> float:
        """The plan time `tau` at simulated time `now` (clamped to the plan, and to the turn
        point of a re-target on the way)."""
        clock = self.clock
        tau = clock.tau + clock.rate * (now - clock.tau_time)
        if self.turn.turn_tau is not None:
            tau = min(tau, self.turn.turn_tau)
        hold = clock.hold_at(now)
        if hold is not None:
            tau = min(tau, hold.tau)
        if clock.plan is None:
            return tau
        # np.clip's arithmetic on a scalar (asked many times an update), without its overhead.
        return float(min(max(tau, 0.0), clock.plan.duration))

    def held(self, now: float) -> bool:
        """Whether the arm stands in a planned wait at `now`."""
        hold = self.clock.hold_at(now)
        return hold is not None and self.plan_time(now) >= hold.tau - 1e-9

    def holding_for_bolts(self, tau: float) -> bool:
        """Whether the robot holds the placed part still, waiting for the operator's bolts."""
        plan = self.plan
        return (
            plan is not None
            and plan.task != UNDO
            and not self.bolted
            and plan.t_in_place <= tau < plan.t_release
        )

    def command(self, now: float) -> ArmCommand:
        """What the arm and the gripper are commanded at `now`."""
        plan = self.plan
        if self.mode == Mode.SETTLE and self.retreat is not None:
            retreat = self.retreat
            return ArmCommand(retreat.positions(now), retreat.velocities(now), self.opening_hold)
        if self.mode != Mode.EXECUTE or plan is None:
            q = np.asarray(self.q_hold, dtype=float)
            return ArmCommand(q, np.zeros(len(q)), self.opening_hold)
        tau = self.plan_time(now)
        q = plan.trajectory.value(tau).ravel()
        v = plan.trajectory.EvalDerivative(tau, 1).ravel() * self.clock.rate
        if tau >= plan.duration:
            v = np.zeros_like(v)
        return ArmCommand(q, v, plan.gripper_opening(tau))

    @property
    def visited(self) -> list[tuple[str, ...]]:
        """The MDP states visited, from the start."""
        return [(), *(r.next_state for r in self.history)]

    def open_detection(self, cause: Cause | None = None) -> bool:
        """Whether a detection of `cause` (None: of any cause) is not resolved yet."""
        return any(d.resolved_at is None and cause in (None, d.cause) for d in self.detections)

    def noted(self, event: str) -> SupervisorStatus:
        """This status with `event` appended to its events."""
        return replace(self, events=(*self.events, event))

    def enter(self, event: Event, settle_until: float | None = None) -> SupervisorStatus:
        """This status in the mode `event` leads to (`transition`: the only place the mode
        changes), settling until `settle_until` if given."""
        until = self.settle_until if settle_until is None else settle_until
        return replace(self, mode=transition(self.mode, event), settle_until=until)


@dataclass(frozen=True, eq=False)  # arrays inside: compared by identity, never by value
class ArmCommand:
    """What the Supervisor commands: the arm's joint positions [rad] and velocities [rad/s],
    and the gripper's opening [m]."""

    q: np.ndarray
    v: np.ndarray
    opening: float


# An obstacle counts as moved (worth planning again) past this distance [m].
OBSTACLE_MOVED = 0.005


def obstacle_moved(planned: tuple[float, ...] | None, seen: tuple[float, ...]) -> bool:
    """Whether the obstacle seen differs from the one planned against (or came or went)."""
    if not planned or not seen:
        return bool(planned) != bool(seen)
    return float(np.linalg.norm(np.subtract(planned[:3], seen[:3]))) > OBSTACLE_MOVED


# The cause of a run ended by its task cap (`run.max_steps`): an operator who keeps undoing can
# outlast any cap; the run ends with that reason, and it is no fault detection.
TASK_CAP = Cause.TASK_CAP


class SupervisorError(RuntimeError):
    """The supervisor cannot go on; `cause` is the Detection cause it reports. With
    `hand_over` the operator can do the task by hand (the part is out of the gripper, the robot
    itself is sound) and the assembly goes on; without, the run stops."""

    def __init__(self, message: str, cause: Cause = Cause.CONFIGURATION, hand_over: bool = False):
        super().__init__(message)
        self.cause = cause
        self.hand_over = hand_over


@dataclass(frozen=True)
class SupervisorLimits:
    """Timing and checks of the Supervisor (from the scenario's `run:` and `station:`)."""

    period: float = 0.02
    settle_time: float = 0.3
    max_steps: int = 30
    joint_acceleration: float = 5.0
    tracking_tolerance: float = 0.05
    grip_tolerance: float = 0.004
    grip_force: float = 20.0
    plan_ahead: bool = True
    indication_timeout: float = 10.0
    indication_give_up: float = 120.0
    recover_tries: int = 2
    path_timeout: float = 10.0
    anticipate: bool = False  # start on the policy's commitment before the indication
    # The guarded descent of a place (`hrc_drake.cell.controller.guard`).
    guard: GuardSettings = field(default_factory=GuardSettings)
    # Seconds the fingers take to open or close (`MotionOptions.gripper_time`).
    gripper_time: float = 0.5

    @property
    def look_ahead(self) -> float:
        """Plan time [s] over which the intent tells the separation monitor the plan's
        velocities (`MotionIntent.ahead`): until a limit the monitor sets now governs what the
        station's safety function judges, `MONITOR_LAG` periods."""
        return MONITOR_LAG * self.period


__all__ = [
    "GRIP_SETTLE",
    "N_JOINTS",
    "OBSTACLE_MOVED",
    "PART_FALL_TIME",
    "TASK_CAP",
    "TRANSITIONS",
    "ArmCommand",
    "Cause",
    "Detection",
    "Event",
    "HeldWait",
    "KeepClearState",
    "Mode",
    "PlanAsk",
    "PlanClock",
    "Question",
    "Recovery",
    "RecoveryState",
    "SupervisorError",
    "SupervisorLimits",
    "SupervisorStatus",
    "TaskInFlight",
    "TaskRecord",
    "TransitionError",
    "TurnState",
    "obstacle_moved",
    "transition",
]
