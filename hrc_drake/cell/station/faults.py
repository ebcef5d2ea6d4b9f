"""The simulated station's fault injector (simulator only): what goes wrong, and when.

The scenario's `faults:` list (`hrc_drake.hri.faults`) says which task each fault strikes; the
injector counts tasks from the prompts the station shows (the N-th task is decision step N,
from the moment its `CHOOSE` prompt appears) and acts only on what a real cell's failure would
act on: the gripper's command as the gripper carries it out, the arm's joints (a push), the
robot's protective-stop input, the operator's answer (`SilentOperator`). The controller never
sees the injector: it detects each fault from its measurements.

Kinds acted on here: `grip-lost` (the grip force drops to `force` `after` s into the carry: the
fingers stalled on the part; until they open again), `gripper-stuck` (the fingers do not close,
or do not open again, in the task), `no-seat` (the part slides `offset` along the pads `after`
s into the carry: the station moves it, `CellStation.apply_welds`, so the robot places it
that far off its seat), `protective-stop` (`safety.stop` is 1 from `after` s into the task for
`duration` s), `pushed` (a torque on `joint` from `after` s into the task for `duration` s),
`tracker-loss` (the body tracker sees nobody from `after` s into the task for `duration` s: the
injector sits between the simulated body and the tracker's port, `operator.body`),
`no-path` (when the task's prompt appears, a box is set down over the seat the robot proposes,
`hrc_drake.cell.station.obstacle`, and taken away `duration` s later), `no-seat` with `obstacle:
true` (when the task's prompt appears, debris drops into the pocket of the seat the robot proposes,
and stays). `operator-silent` is the
simulated operator's (`SilentOperator`); the injector notes when its task's prompt appears.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.ports import NOBODY
from hrc_drake.cell.station.gripper import STALL_GAP, stopped_short
from hrc_drake.cell.station.obstacle import SeatPositions
from hrc_drake.hri.faults import (
    FaultConfig,
    FaultKind,
    GripLost,
    GripperStuck,
    NoPath,
    NoSeat,
    OperatorSilent,
    ProtectiveStop,
    Pushed,
    SafetySensorSilent,
    Stuck,
    TrackerLoss,
)
from hrc_drake.hri.messages import Prompt, PromptKind
from hrc_drake.obstacle_models import DEBRIS_PARK, OBSTACLE_PARK, obstacle_pose_over
from hrc_drake.tasks.protocols import DelaysIndications

# The faults that act for `duration` s from `after` s into their task.
TimedFault = ProtectiveStop | Pushed | TrackerLoss | SafetySensorSilent
# The fingers count as standing still below this rate (they close at about 0.5 m/s).
STILL_RATE = 0.005  # m/s
# The box of a no-path fault moves under the table to below its seat, then rises into place
# this long after the prompt; the operator, who set it down, answers OBSTACLE_SET_TIME after
# the prompt (`SilentOperator`), once it stands there.
OBSTACLE_RISE_DELAY = 0.3  # s
OBSTACLE_SET_TIME = 1.0  # s


@dataclass(frozen=True)
class Injection:
    """One fault as the injector carried it out (times in simulated seconds; None: not yet)."""

    kind: str
    task: int
    task_start: float | None = None  # when the task's CHOOSE prompt appeared
    injected_at: float | None = None
    since: float | None = None  # grip-lost: the carry began; stuck open: the fingers stalled
    # grip-lost: the fingers opened again (the fault is over); no-seat with debris: the
    # operator cleared the pocket.
    ended_at: float | None = None
    shifted: bool = False  # no-seat: the station has moved the part in the fingers
    target: tuple[float, ...] = ()  # no-path: where the box stands (its centre, world)

    def __deepcopy__(self, memo) -> Injection:
        return self

    def to_json(self) -> dict:
        """The JSON-able record, every field (the station's session report carries it over LCM,
        `hrc_drake.cell.link.station_record`); floats as they are, so `from_json` gives it back
        exactly."""
        return {
            "kind": self.kind,
            "task": self.task,
            "task_start": self.task_start,
            "injected_at": self.injected_at,
            "since": self.since,
            "ended_at": self.ended_at,
            "shifted": self.shifted,
            "target": list(self.target),
        }

    @classmethod
    def from_json(cls, data: dict) -> Injection:
        """The record `to_json` gave (KeyError or TypeError for a field missing or unknown)."""
        return cls(**{**data, "target": tuple(float(v) for v in data["target"])})


def _window(fault: TimedFault, injection: Injection, now: float) -> bool:
    """Whether a timed fault (stop, push, tracker loss, silent sensor) acts at `now`."""
    if injection.task_start is None:
        return False
    start = injection.task_start + fault.after
    return start <= now < start + fault.duration


def _carriage_state(park, placed, now: float) -> np.ndarray:
    """The desired state (x, y, z, three zero rates) of the box's or the debris's carriage:
    at `park` until a fault of `placed` ((injection, seconds it lasts) pairs) strikes; then at
    its target's x, y (under the table for the box, high above for the debris), and at the
    target itself OBSTACLE_RISE_DELAY s later, until it has lasted."""
    where = np.array(park, dtype=float)
    for injection, lasts in placed:
        if not injection.target:
            continue
        since = now - injection.injected_at
        if since < lasts:
            where[:2] = injection.target[:2]
        if OBSTACLE_RISE_DELAY <= since < lasts:
            where[2] = injection.target[2]
    return np.concatenate([where, np.zeros(3)])


class FaultInjector(LeafSystem):
    """Carries out `faults` (see the module docstring).

    Input ports: `hri.prompt` (Prompt), `opening` and `force` (the gripper's command after its
    range clip, 1 each), `measured` (the gripper's opening and rate, 2). Output ports: `opening`,
    `force` (the command the fingers' servo obeys), `safety.stop` (1), `torque` (the plant's
    generalized forces), `obstacle` and `debris` (their carriages' desired states: x, y, z,
    then three zero rates), `injected` (tuple of Injection). With a `tracker-loss` fault also
    an input and an output `operator.body` (BodySpheres): the body as the tracker sees it, NOBODY
    while a loss acts (`has_tracker_loss`). Updated every `period` seconds.
    `seat_position` (a `hrc_drake.cell.station.obstacle.SeatPositions`) places a no-path fault's box
    and a no-seat fault's debris."""

    def __init__(
        self,
        plant: MultibodyPlant,
        faults: Sequence[FaultConfig],
        period: float,
        seat_position: SeatPositions | None = None,
        units: Sequence[str] = (),
    ):
        super().__init__()
        self._faults = tuple(faults)
        self._seat_position = seat_position
        self._nv = plant.num_velocities()
        self._dof = {}
        for fault in self._faults:
            if isinstance(fault, Pushed):
                self._dof[fault.joint] = plant.GetJointByName(fault.joint).velocity_start()
        self._prompt = self.DeclareAbstractInputPort("hri.prompt", AbstractValue.Make(Prompt()))
        self._opening = self.DeclareVectorInputPort("opening", BasicVector(1))
        self._force = self.DeclareVectorInputPort("force", BasicVector(1))
        self._measured = self.DeclareVectorInputPort("measured", BasicVector(2))
        initial = tuple(Injection(f.kind.value, f.task) for f in self._faults)
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.DeclareVectorOutputPort("opening", BasicVector(1), self._calc_opening)
        self.DeclareVectorOutputPort("force", BasicVector(1), self._calc_force)
        self.DeclareVectorOutputPort("safety.stop", BasicVector(1), self._calc_stop)
        self.DeclareVectorOutputPort("torque", BasicVector(self._nv), self._calc_torque)
        self.DeclareVectorOutputPort("obstacle", BasicVector(6), self._calc_obstacle)
        self.DeclareVectorOutputPort("debris", BasicVector(6), self._calc_debris)
        self.DeclareStateOutputPort("injected", self._state)
        self.has_tracker_loss = any(isinstance(f, TrackerLoss) for f in self._faults)
        if self.has_tracker_loss:  # only then: every other station's diagram is as it was
            self._body = self.DeclareAbstractInputPort("operator.body", AbstractValue.Make(NOBODY))
            self.DeclareAbstractOutputPort(
                "operator.body",
                lambda: AbstractValue.Make(NOBODY),
                self._calc_body,
                prerequisites_of_calc={
                    self.time_ticket(),
                    self.abstract_state_ticket(self._state),
                    self.input_port_ticket(self._body.get_index()),
                },
            )
        self._units = tuple(units)
        self.has_silent_sensor = any(isinstance(f, SafetySensorSilent) for f in self._faults)
        if self.has_silent_sensor:
            self.DeclareVectorOutputPort(
                "safety_sensor.silent",
                BasicVector(len(self._units)),
                self._calc_silent,
                prerequisites_of_calc={self.time_ticket(), self.abstract_state_ticket(self._state)},
            )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def _injections(self, context) -> tuple[Injection, ...]:
        return context.get_abstract_state(self._state).get_value()

    def _active(self, context, cls: type):
        """(fault, injection) pairs of the faults of class `cls` whose task has begun."""
        for fault, injection in zip(self._faults, self._injections(context), strict=True):
            if isinstance(fault, cls) and injection.task_start is not None:
                yield fault, injection

    def _in_task(self, context, injection: Injection) -> bool:
        prompt: Prompt = self._prompt.Eval(context)
        return injection.task_start is not None and prompt.step == injection.task

    # --- outputs -------------------------------------------------------------------------
    def _calc_opening(self, context, output) -> None:
        opening = float(self._opening.Eval(context)[0])
        measured = float(self._measured.Eval(context)[0])
        for fault, injection in self._active(context, GripperStuck):
            if not self._in_task(context, injection):
                continue
            if fault.stuck == Stuck.CLOSE:
                opening = max(opening, measured)  # the fingers can open, never close
            elif injection.since is not None:
                opening = min(opening, measured)  # closed on the part, they never open
        output.SetFromVector([opening])

    def _calc_force(self, context, output) -> None:
        force = float(self._force.Eval(context)[0])
        for fault, injection in self._active(context, GripLost):
            lost = injection.injected_at is not None and injection.ended_at is None
            if lost and self._in_task(context, injection):
                force = min(force, fault.force)
        output.SetFromVector([force])

    def _calc_stop(self, context, output) -> None:
        now = context.get_time()
        stop = any(_window(f, i, now) for f, i in self._active(context, ProtectiveStop))
        output.SetFromVector([1.0 if stop else 0.0])

    def _calc_torque(self, context, output) -> None:
        now = context.get_time()
        torque = np.zeros(self._nv)
        for fault, injection in self._active(context, Pushed):
            if _window(fault, injection, now):
                torque[self._dof[fault.joint]] += fault.torque
        output.SetFromVector(torque)

    def _calc_obstacle(self, context, output) -> None:
        boxes = ((i, f.duration) for f, i in self._active(context, NoPath))
        output.SetFromVector(_carriage_state(OBSTACLE_PARK, boxes, context.get_time()))

    def _calc_debris(self, context, output) -> None:
        # The debris stays until the operator clears it (a task handed over: `clear_debris`).
        debris = (
            (i, np.inf if i.ended_at is None else i.ended_at - i.injected_at)
            for f, i in self._active(context, NoSeat)
            if f.obstacle and i.injected_at is not None
        )
        output.SetFromVector(_carriage_state(DEBRIS_PARK, debris, context.get_time()))

    def _calc_body(self, context, output) -> None:
        # Lost: nobody, current (no stamp: now; a sensor model after it stamps its samples).
        now = context.get_time()
        lost = any(_window(f, i, now) for f, i in self._active(context, TrackerLoss))
        output.set_value(NOBODY if lost else self._body.Eval(context))

    def _calc_silent(self, context, output) -> None:
        now = context.get_time()
        silent = np.zeros(len(self._units))
        for fault, injection in self._active(context, SafetySensorSilent):
            if _window(fault, injection, now):
                silent[[not fault.unit or fault.unit == u for u in self._units]] = 1.0
        output.SetFromVector(silent)

    # --- what happened -------------------------------------------------------------------
    def _update(self, context, state) -> None:
        now = context.get_time()
        prompt: Prompt = self._prompt.Eval(context)
        updated = []
        for fault, injection in zip(self._faults, self._injections(context), strict=True):
            if injection.task_start is None:
                if prompt.kind == PromptKind.CHOOSE and prompt.step == fault.task:
                    injection = replace(injection, task_start=now)
                    if isinstance(fault, OperatorSilent):
                        injection = replace(injection, injected_at=now)
                    if isinstance(fault, NoPath) or (isinstance(fault, NoSeat) and fault.obstacle):
                        injection = self._set_down(fault, injection, prompt, now)
            elif injection.injected_at is None and prompt.step == fault.task:
                injection = self._inject(context, fault, injection, now)
            elif injection.ended_at is None and isinstance(fault, GripLost):
                injection = self._end_grip_loss(context, injection, now)
            updated.append(injection)
        state.get_mutable_abstract_state(self._state).set_value(tuple(updated))

    def _inject(self, context, fault: FaultConfig, injection: Injection, now: float):
        """The moment a fault of the running task takes effect, if it is now."""
        if isinstance(fault, TimedFault):
            if now >= injection.task_start + fault.after:
                return replace(injection, injected_at=now)
            return injection
        command, opening, rate = self._fingers(context)
        # The fingers stand still short of their target: on a part (or stuck).
        stalled = stopped_short(opening, command) and abs(rate) < STILL_RATE
        if isinstance(fault, NoSeat | GripLost):
            return self._in_carry(fault, injection, stalled, now)
        if not isinstance(fault, GripperStuck):
            return injection
        if fault.stuck == Stuck.CLOSE and stalled:
            return replace(injection, injected_at=now)  # a close the fingers do not obey
        if fault.stuck == Stuck.OPEN:
            if injection.since is None:
                return replace(injection, since=now) if stalled else injection
            if command - opening > STALL_GAP:  # an open the fingers do not obey
                return replace(injection, injected_at=now)
        return injection

    def _set_down(self, fault: NoPath | NoSeat, injection: Injection, prompt: Prompt, now: float):
        """A no-path fault's box goes over the seat the robot proposes; a no-seat fault's
        debris into its pocket."""
        seats = self._seat_position
        if seats is None:
            raise ValueError(f"a {fault.kind} fault needs the station's seat positions")
        if isinstance(fault, NoPath):
            where = obstacle_pose_over(seats(prompt)).translation()
        else:
            where = seats.pocket(prompt)
        return replace(injection, injected_at=now, target=tuple(float(v) for v in where))

    @staticmethod
    def _in_carry(fault: NoSeat | GripLost, injection: Injection, stalled: bool, now: float):
        """Faults of the carry strike `after` s after the fingers stalled on the part (the
        part lifted clear of the tray: sliding it in the fingers there would push it into the
        tray's pocket)."""
        if not stalled:
            return replace(injection, since=None)
        since = now if injection.since is None else injection.since
        if now - since >= fault.after:
            return replace(injection, injected_at=now, since=since)
        return replace(injection, since=since)

    def _end_grip_loss(self, context, injection: Injection, now: float) -> Injection:
        """A lost grip lasts until the fingers are told to open again (a new grasp grips)."""
        command, opening, _ = self._fingers(context)
        return replace(injection, ended_at=now) if command - opening > STALL_GAP else injection

    def _fingers(self, context) -> tuple[float, float, float]:
        """(commanded opening, measured opening, measured rate) of the gripper."""
        opening, rate = self._measured.Eval(context)
        return float(self._opening.Eval(context)[0]), float(opening), float(rate)

    def pending_shifts(self, context) -> list[tuple[int, NoSeat]]:
        """(index, fault) of the no-seat faults injected whose part the station has not moved
        in the fingers yet (`context`: this system's)."""
        return [
            (k, fault)
            for k, (fault, injection) in enumerate(
                zip(self._faults, self._injections(context), strict=True)
            )
            if isinstance(fault, NoSeat)
            and not fault.obstacle
            and injection.injected_at is not None
            and not injection.shifted
        ]

    def clear_debris(self, context) -> bool:
        """The operator takes the debris of the no-seat faults out of its pocket now (their
        carriage parks): in `context` (this system's). Whether there was any."""
        injections, now, cleared = list(self._injections(context)), context.get_time(), False
        for k, (fault, injection) in enumerate(zip(self._faults, injections, strict=True)):
            if (
                isinstance(fault, NoSeat)
                and fault.obstacle
                and injection.injected_at is not None
                and injection.ended_at is None
            ):
                injections[k], cleared = replace(injection, ended_at=now), True
        context.get_mutable_abstract_state(self._state).set_value(tuple(injections))
        return cleared

    def mark_shifted(self, context, index: int) -> None:
        """Record in `context` (this system's) that the part of fault `index` was moved."""
        injections = list(self._injections(context))
        injections[index] = replace(injections[index], shifted=True)
        context.get_mutable_abstract_state(self._state).set_value(tuple(injections))


class SilentOperator:
    """The simulated operator with the `operator-silent` and `no-path` faults: the answer to
    each silent task's choice comes `duration` s later than the operator would give it (its own
    `indication_delay`, if it has one, plus the silence); to a no-path task's,
    OBSTACLE_SET_TIME later (the box is set down first)."""

    KINDS = (FaultKind.OPERATOR_SILENT, FaultKind.NO_PATH)

    def __init__(self, operator, faults: Sequence[FaultConfig]):
        self._operator = operator
        self._silence: dict[int, float] = {}
        for f in faults:
            if isinstance(f, OperatorSilent):
                self._silence[f.task] = self._silence.get(f.task, 0.0) + f.duration
            elif isinstance(f, NoPath):
                self._silence[f.task] = self._silence.get(f.task, 0.0) + OBSTACLE_SET_TIME

    def __call__(self, step, state, proposal):
        return self._operator(step, state, proposal)

    def __getattr__(self, name):
        return getattr(self._operator, name)

    def indication_delay(self, step: int) -> float:
        """Seconds from the prompt of `step` to the answer."""
        operator = self._operator
        own = operator.indication_delay(step) if isinstance(operator, DelaysIndications) else 0.0
        return float(own) + self._silence.get(step, 0.0)


__all__ = ["FaultInjector", "Injection", "SilentOperator"]
