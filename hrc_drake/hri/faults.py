"""Faults a scenario injects into the simulated cell, and what the run reports of them.

A scenario's `faults:` list holds one tagged entry per fault, as Drake's `model_drivers` hold
their drivers: the tag names the kind (`!GripLost`, the class of that name below) and the
mapping gives the task it strikes (`task: N`, the N-th task of the run, from 1) and the kind's
own parameters, each with a default, so that `!GripLost {task: 2}` alone is a valid entry:

    faults: [!GripLost {task: 2}, !Pushed {task: 1, torque: 150}]

The station injects them (`hrc_drake.cell.station.faults`); the controller never reads this
list: it detects every fault from what it measures (the gripper, the configuration sensor, joint
tracking, the protective-stop input, the operator's silence) and recovers or hands the task over
to the operator. The run reports each by its kind (`FaultKind`, e.g. `grip-lost`).

Kinds, their tags and their parameters (defaults in brackets):

- `grip-lost` (`!GripLost`): the grip force drops to `force` N [1.0] `after` s [1.0] into the
  carry, until the fingers open again; the part falls where physics puts it.
- `no-seat` (`!NoSeat`): the part cannot seat: it slides `offset` m [0.008] along the pads
  `after` s [0.8] into the carry (lifted clear of the tray), so it is placed that far off its
  seat; or, with `obstacle: true` [false], debris too small for the cell to see drops into the
  pocket of the seat the robot proposes when the task's prompt appears, and stays (the part
  lands on it).
- `gripper-stuck` (`!GripperStuck`): the gripper does not close (`stuck: close`, the default)
  or open (`stuck: open`).
- `no-path` (`!NoPath`): a temporary obstacle (a box) stands over the seat of the task the robot
  proposes from the task's prompt on, for `duration` s [6.0]; the operator, who set it down,
  answers 1 s after the prompt.
- `operator-silent` (`!OperatorSilent`): the operator gives no indication for `duration` s
  [15.0].
- `protective-stop` (`!ProtectiveStop`): an external stop signal `after` s [4.0] into the task,
  for `duration` s [2.0].
- `pushed` (`!Pushed`): a torque of `torque` N·m [80] on `joint` [shoulder_pan_joint] `after` s
  [4.0] into the task, for `duration` s [0.3].
- `tracker-loss` (`!TrackerLoss`): the body tracker (`operator.body`, what the controller reads)
  loses the person `after` s [4.0] into the task, for `duration` s [1.0]: it reports nobody (an
  empty reading, current, not stale); the person, the station's safety function and the run's
  check are unchanged. The controller takes the person to be anywhere they could have reached
  since last seen (`hrc_drake.cell.controller.body_memory`); it has no detection to report.
- `safety-sensor-silent` (`!SafetySensorSilent`): a unit of the safety-rated sensor (`unit`, by
  name [every unit]) sends no frames `after` s [4.0] into the task, for `duration` s [1.0]
  (needs `safety.sensor.enabled`); the safety function takes a safeguard stop within the
  unit's response time and a period, which the controller sees as a stop.
"""

import dataclasses
import typing
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import ClassVar


class FaultKind(StrEnum):
    """The kinds of fault a scenario can inject (what the run's report calls them)."""

    GRIP_LOST = "grip-lost"
    NO_SEAT = "no-seat"
    GRIPPER_STUCK = "gripper-stuck"
    NO_PATH = "no-path"
    OPERATOR_SILENT = "operator-silent"
    PROTECTIVE_STOP = "protective-stop"
    PUSHED = "pushed"
    TRACKER_LOSS = "tracker-loss"
    SAFETY_SENSOR_SILENT = "safety-sensor-silent"


class Stuck(StrEnum):
    """Which command a stuck gripper does not obey (`GripperStuck.stuck`)."""

    CLOSE = "close"  # the fingers can open, never close
    OPEN = "open"  # closed on the part, they never open again


# Plain (not frozen) dataclasses: Drake's `yaml_load_typed` sets their fields one by one.
@dataclass
class GripLost:
    """`grip-lost`: the grip force drops to `force` N `after` s into the carry (from the
    fingers' stall on the part), until the fingers open again."""

    kind: ClassVar[FaultKind] = FaultKind.GRIP_LOST
    task: int = 0
    force: float = 1.0
    after: float = 1.0


@dataclass
class NoSeat:
    """`no-seat`: the part slides `offset` m along the pads `after` s into the carry (from the
    fingers' stall on the part); or, with `obstacle`, debris drops into the pocket of the seat
    the robot proposes when the task's prompt appears (`offset` and `after` unused)."""

    kind: ClassVar[FaultKind] = FaultKind.NO_SEAT
    task: int = 0
    offset: float = 0.008
    after: float = 0.8
    obstacle: bool = False


@dataclass
class GripperStuck:
    """`gripper-stuck`: the fingers do not obey `stuck` (a `Stuck`: close or open) in the task.
    Text, not the enum, so that Drake's loader reads it too."""

    kind: ClassVar[FaultKind] = FaultKind.GRIPPER_STUCK
    task: int = 0
    stuck: str = Stuck.CLOSE.value


@dataclass
class NoPath:
    """`no-path`: a box stands over the seat the robot proposes for `duration` s from the
    task's prompt."""

    kind: ClassVar[FaultKind] = FaultKind.NO_PATH
    task: int = 0
    duration: float = 6.0


@dataclass
class OperatorSilent:
    """`operator-silent`: the operator gives no indication for `duration` s."""

    kind: ClassVar[FaultKind] = FaultKind.OPERATOR_SILENT
    task: int = 0
    duration: float = 15.0


@dataclass
class ProtectiveStop:
    """`protective-stop`: an external stop signal `after` s into the task, for `duration` s."""

    kind: ClassVar[FaultKind] = FaultKind.PROTECTIVE_STOP
    task: int = 0
    after: float = 4.0
    duration: float = 2.0


@dataclass
class Pushed:
    """`pushed`: a torque of `torque` N·m on `joint` `after` s into the task, for `duration`
    s."""

    kind: ClassVar[FaultKind] = FaultKind.PUSHED
    task: int = 0
    torque: float = 80.0
    joint: str = "shoulder_pan_joint"
    after: float = 4.0
    duration: float = 0.3


# A fault, not a figure of `sensors.body`: the `sensors:` section models how a device reads
# (rate, latency, noise, random dropouts) the same at every step, while a loss is one event the
# station injects at a scripted moment and the controller must cope with unaided, as with every
# entry here; and timed like `!ProtectiveStop` (`after` s into the `task`-th task) so that it
# strikes the same moment of the task (say, the hand's reach toward the arm) whatever came before.
@dataclass
class TrackerLoss:
    """`tracker-loss`: the body tracker reports nobody `after` s into the task, for `duration` s
    (the person is there all along)."""

    kind: ClassVar[FaultKind] = FaultKind.TRACKER_LOSS
    task: int = 0
    after: float = 4.0
    duration: float = 1.0


@dataclass
class SafetySensorSilent:
    """`safety-sensor-silent`: a unit of the safety-rated sensor (`unit`, by name; "": every
    unit) sends no frames `after` s into the task, for `duration` s."""

    kind: ClassVar[FaultKind] = FaultKind.SAFETY_SENSOR_SILENT
    task: int = 0
    after: float = 4.0
    duration: float = 1.0
    unit: str = ""


# One entry of a scenario's `faults:` list: the YAML tag (`!GripLost`) chooses the member.
FaultConfig = (
    GripLost
    | NoSeat
    | GripperStuck
    | NoPath
    | OperatorSilent
    | ProtectiveStop
    | Pushed
    | TrackerLoss
    | SafetySensorSilent
)

# The entry's class of each kind (its YAML tag is the class's name: `!GripLost`).
FAULT_CLASSES: dict[FaultKind, type] = {cls.kind: cls for cls in typing.get_args(FaultConfig)}

# The kinds the simulated cell injects and the controller handles so far.
SIMULATED = (
    FaultKind.GRIP_LOST,
    FaultKind.NO_SEAT,
    FaultKind.GRIPPER_STUCK,
    FaultKind.NO_PATH,
    FaultKind.OPERATOR_SILENT,
    FaultKind.PROTECTIVE_STOP,
    FaultKind.PUSHED,
    FaultKind.TRACKER_LOSS,
    FaultKind.SAFETY_SENSOR_SILENT,
)


class FaultError(ValueError):
    """A fault entry that cannot be used; the message names the entry and the fix."""


def _named(source: str) -> str:
    """Where a faults list came from, as an error names it: `scenario FILE`, or the option
    (`--scenario-text`) that gave it."""
    return source if source.startswith("--") else f"scenario {source}"


def check_faults(
    faults: list[FaultConfig], source: str, joints: Sequence[str] | None = None
) -> None:
    """Value checks of a `faults:` list (once, when the scenario is loaded): FaultError naming
    the entry (`faults[i]`) for an entry that is not a fault, a task before 1, a negative or
    out-of-range parameter, or a pushed joint not among `joints` (the robot's)."""
    for i, fault in enumerate(faults):
        if not isinstance(fault, FaultConfig):
            tags = ", ".join(f"!{cls.__name__}" for cls in FAULT_CLASSES.values())
            raise FaultError(
                f"{_named(source)}: faults[{i}]: {fault!r} is not a fault; give one of {tags}"
            )
        kind = fault.kind
        where = f"{_named(source)}: faults[{i}] ({kind.value})"
        if kind not in SIMULATED:
            built = ", ".join(k.value for k in SIMULATED)
            raise FaultError(
                f"{where}: the cell does not simulate {kind.value} faults yet; use one of {built}"
            )
        if fault.task < 1:
            raise FaultError(f"{where}: task {fault.task}: tasks count from 1 (the run's first)")
        _check_values(fault, where)
        if isinstance(fault, Pushed) and joints is not None and fault.joint not in joints:
            raise FaultError(
                f"{where}: joint {fault.joint!r} is not the robot's; use one of {', '.join(joints)}"
            )


def check_faults_within_run(faults: list[FaultConfig], source: str, tasks: int) -> None:
    """FaultError naming the first entry whose task is past a run of `tasks` tasks (known
    before the run when the operator's choices are)."""
    for i, fault in enumerate(faults):
        if fault.task > tasks:
            raise FaultError(
                f"{_named(source)}: faults[{i}] ({fault.kind.value}): task {fault.task} is past "
                f"the run, which has {tasks} task(s); choose a task within it"
            )


def _check_values(fault: FaultConfig, where: str) -> None:
    """The signs of the parameters the fault's kind has, then each kind's own ranges."""
    own = [f.name for f in dataclasses.fields(fault)]
    for name in ("force", "offset", "torque"):
        if name in own and getattr(fault, name) < 0:
            raise FaultError(f"{where}: {name} {getattr(fault, name)} must be >= 0")
    for name in ("after", "duration"):
        if name in own and getattr(fault, name) < 0:
            raise FaultError(f"{where}: {name} {getattr(fault, name)} must be >= 0 (seconds)")
    if isinstance(fault, GripLost) and fault.force >= 3.0:
        raise FaultError(
            f"{where}: force {fault.force} N is a grip the RG2 can hold (3-40 N); a lost grip "
            "drops below 3 N"
        )
    if isinstance(fault, NoSeat) and not fault.obstacle and fault.offset <= 0.0015:
        raise FaultError(
            f"{where}: offset {fault.offset} m lets the part seat (the pockets have 1.5 mm of "
            "clearance); give more than 0.0015, or obstacle: true"
        )
    if isinstance(fault, GripperStuck) and fault.stuck not in {s.value for s in Stuck}:
        raise FaultError(f"{where}: stuck {fault.stuck!r}: give close or open")


@dataclass(frozen=True)
class FaultRecord:
    """What a run reports of one fault (`simulate --json` `faults`), times in simulated
    seconds. `recovered` is true only when the cell itself recovered and the assembly went on;
    `recovery` is a short word (`regrasp`, `replace`, `retry`, `operator`, `resume`, `ask`;
    `monitoring` for a fault no measurement shows, which the run rode through)."""

    kind: str
    task: int
    injected_at: float | None
    detected_at: float | None
    recovered: bool
    recovery: str
    seconds_lost: float

    def to_json(self) -> dict:
        """The JSON-able record."""

        def time(t: float | None) -> float | None:
            return None if t is None else round(t, 3)

        return {
            "kind": self.kind,
            "task": self.task,
            "injected_at": time(self.injected_at),
            "detected_at": time(self.detected_at),
            "recovered": self.recovered,
            "recovery": self.recovery,
            "seconds_lost": round(self.seconds_lost, 3),
        }


__all__ = [
    "FAULT_CLASSES",
    "FaultConfig",
    "FaultError",
    "FaultKind",
    "FaultRecord",
    "GripLost",
    "GripperStuck",
    "NoPath",
    "NoSeat",
    "OperatorSilent",
    "ProtectiveStop",
    "Pushed",
    "SafetySensorSilent",
    "Stuck",
    "TrackerLoss",
    "check_faults",
    "check_faults_within_run",
]
