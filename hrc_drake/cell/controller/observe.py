"""What the cell shows after a task: the task done, read from the configuration sensor (the part
may sit in another seat than planned), and the record of the task as it happened. Values only;
the Supervisor acts on them (`hrc_drake.cell.controller.supervisor`)."""

from __future__ import annotations

from hrc_drake.cell.controller.supervisor_state import (
    Cause,
    SupervisorError,
    SupervisorStatus,
    TaskRecord,
)
from hrc_drake.cell.ports import CellConfiguration
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO


def cell_shows(
    s: SupervisorStatus, config: CellConfiguration, space: StateSpace
) -> tuple[str, tuple[str, ...]]:
    """(the task the cell shows done, the next MDP state); SupervisorError if the cell shows
    something no task explains."""
    indicated, part = s.task.indicated, s.task.part
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
            cause=Cause.SEAT,
            # Out of its seat, out of the gripper, nothing else moved: the operator can seat
            # it (unless they did the task already).
            hand_over=not removed and not added and not s.recovery.handover,
        )
    (observed,) = added
    if observed not in {t for t, _ in space.tasks(space.index(s.state))}:
        raise SupervisorError(
            f"the cell shows {observed} placed, not a feasible task from {list(s.state)}"
        )
    return observed, (*s.state, observed)


def task_record(
    s: SupervisorStatus, observed: str, next_state: tuple[str, ...], part: str, now: float
) -> TaskRecord:
    """The task in flight as it happened, ending at `now`."""
    ask, question, turn = s.ask, s.question, s.turn
    return TaskRecord(
        step=s.step,
        state=s.state,
        proposed=s.task.proposed,
        indicated=s.task.indicated,
        observed=observed,
        next_state=next_state,
        part=part,
        start_time=s.clock.plan_start,
        end_time=now,
        idle=ask.idle,
        wall_idle=ask.wall_idle,
        plan_ready=ask.plan_ready,
        committed=turn.committed,
        indicated_at=question.indicated_at,
        held_at=question.held_at,
        retargeted=turn.retargeted,
        swapped=turn.swapped,
        handed_over=s.recovery.handover,
    )


__all__ = ["cell_shows", "task_record"]
