"""Faults a scenario injects into the simulated cell, and what the run reports of them.

A scenario's `faults:` list names, per entry, a kind and the task it strikes (`task: N`, the N-th
task of the run, from 1) and the kind's parameters, each with a default, so that `{kind: K,
task: N}` alone is a valid entry. The station injects them (`hrc_drake.cell.station.faults`); the
controller never reads this list: it detects every fault from what it measures (the gripper,
the configuration sensor, joint tracking, the protective-stop input, the operator's silence) and
recovers or hands the task over to the operator.

Kinds (`FaultKind`) and their parameters (defaults in brackets):

- `grip-lost`: the grip force drops to `force` N [1.0] `after` s [1.0] into the carry, until the
  fingers open again; the part falls where physics puts it.
- `no-seat`: the part cannot seat: it slides `offset` m [0.008] along the pads `after` s [0.8]
  into the carry (lifted clear of the tray), so it is placed that far off its seat; or, with
  `obstacle: true`, debris too small for the cell to see drops into the pocket of the seat the
  robot proposes when the task's prompt appears, and stays (the part lands on it).
- `gripper-stuck`: the gripper does not close (`stuck: close`) or open (`stuck: open`).
- `no-path`: a temporary obstacle (a box) stands over the seat of the task the robot proposes
  from the task's prompt on, for `duration` s [6.0]; the operator, who set it down, answers 1 s
  after the prompt.
- `operator-silent`: the operator gives no indication for `duration` s [15.0].
- `protective-stop`: an external stop signal `after` s [4.0] into the task, for `duration` s
  [2.0].
- `pushed`: a torque of `torque` N·m [80] on `joint` [shoulder_pan_joint] `after` s [4.0] into
  the task, for `duration` s [0.3].
"""

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum


class FaultKind(StrEnum):
    """The kinds of fault a scenario can inject."""

    GRIP_LOST = "grip-lost"
    NO_SEAT = "no-seat"
    GRIPPER_STUCK = "gripper-stuck"
    NO_PATH = "no-path"
    OPERATOR_SILENT = "operator-silent"
    PROTECTIVE_STOP = "protective-stop"
    PUSHED = "pushed"


@dataclass
class FaultConfig:
    """One fault of a scenario's `faults:` list (see the module docstring for each kind's
    parameters; those of other kinds are left at their defaults)."""

    kind: str = ""
    task: int = 0
    force: float = 1.0
    after: float = -1.0  # -1: the kind's default (see `after_seconds`)
    offset: float = 0.008
    obstacle: bool = False
    stuck: str = "close"
    duration: float = -1.0  # -1: the kind's default (see `duration_seconds`)
    torque: float = 80.0
    joint: str = "shoulder_pan_joint"

    @property
    def fault_kind(self) -> FaultKind:
        """The kind as an enum (ValueError for an unknown kind)."""
        return FaultKind(self.kind)

    @property
    def after_seconds(self) -> float:
        """Seconds into the carry (grip-lost, no-seat: from the fingers' stall on the part) or
        into the task (protective-stop, pushed)."""
        if self.after >= 0:
            return self.after
        if self.fault_kind in (FaultKind.GRIP_LOST, FaultKind.NO_SEAT):
            return 1.0 if self.fault_kind == FaultKind.GRIP_LOST else 0.8
        return 4.0

    @property
    def duration_seconds(self) -> float:
        """How long the fault lasts (no-path, operator-silent, protective-stop, pushed)."""
        if self.duration >= 0:
            return self.duration
        return {
            FaultKind.NO_PATH: 6.0,
            FaultKind.OPERATOR_SILENT: 15.0,
            FaultKind.PROTECTIVE_STOP: 2.0,
            FaultKind.PUSHED: 0.3,
        }.get(self.fault_kind, 0.0)


# The kinds the simulated cell injects and the controller handles so far.
SIMULATED = (
    FaultKind.GRIP_LOST,
    FaultKind.NO_SEAT,
    FaultKind.GRIPPER_STUCK,
    FaultKind.NO_PATH,
    FaultKind.OPERATOR_SILENT,
    FaultKind.PROTECTIVE_STOP,
    FaultKind.PUSHED,
)


class FaultError(ValueError):
    """A fault entry that cannot be used; the message names the entry and the fix."""


def check_faults(
    faults: list[FaultConfig],
    source: str,
    max_tasks: int | None = None,
    joints: Sequence[str] | None = None,
) -> None:
    """Value checks of a `faults:` list: FaultError naming the entry (`faults[i]`) for an unknown
    kind, a task before 1 (or past `max_tasks`, the run's length when it is known), a negative or
    out-of-range parameter, or a pushed joint not among `joints` (the robot's, when known)."""
    kinds = ", ".join(k.value for k in FaultKind)
    for i, fault in enumerate(faults):
        where = f"scenario {source}: faults[{i}] ({fault.kind or 'no kind'})"
        try:
            kind = fault.fault_kind
        except ValueError:
            raise FaultError(f"{where}: unknown kind {fault.kind!r}; kinds are {kinds}") from None
        if kind not in SIMULATED:
            built = ", ".join(k.value for k in SIMULATED)
            raise FaultError(
                f"{where}: the cell does not simulate {kind.value} faults yet; use one of {built}"
            )
        if fault.task < 1:
            raise FaultError(f"{where}: task {fault.task}: tasks count from 1 (the run's first)")
        if max_tasks is not None and fault.task > max_tasks:
            raise FaultError(
                f"{where}: task {fault.task} is past the run, which has {max_tasks} task(s); "
                "choose a task within it"
            )
        _check_values(fault, kind, where)
        if kind == FaultKind.PUSHED and joints is not None and fault.joint not in joints:
            raise FaultError(
                f"{where}: joint {fault.joint!r} is not the robot's; use one of {', '.join(joints)}"
            )


def _check_values(fault: FaultConfig, kind: FaultKind, where: str) -> None:
    for name in ("force", "offset", "torque"):
        if getattr(fault, name) < 0:
            raise FaultError(f"{where}: {name} {getattr(fault, name)} must be >= 0")
    for name in ("after", "duration"):
        value = getattr(fault, name)
        if value < 0 and value != -1.0:
            raise FaultError(f"{where}: {name} {value} must be >= 0 (seconds)")
    if kind == FaultKind.GRIP_LOST and fault.force >= 3.0:
        raise FaultError(
            f"{where}: force {fault.force} N is a grip the RG2 can hold (3-40 N); a lost grip "
            "drops below 3 N"
        )
    if kind == FaultKind.NO_SEAT and not fault.obstacle and fault.offset <= 0.0015:
        raise FaultError(
            f"{where}: offset {fault.offset} m lets the part seat (the pockets have 1.5 mm of "
            "clearance); give more than 0.0015, or obstacle: true"
        )
    if fault.stuck not in ("close", "open"):
        raise FaultError(f"{where}: stuck {fault.stuck!r}: give close or open")


@dataclass(frozen=True)
class FaultRecord:
    """What a run reports of one fault (`simulate --json` `faults`), times in simulated
    seconds. `recovered` is true only when the cell itself recovered and the assembly went on;
    `recovery` is a short word (`regrasp`, `replace`, `retry`, `operator`, `resume`, `ask`)."""

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


__all__ = ["FaultConfig", "FaultError", "FaultKind", "FaultRecord", "check_faults"]
