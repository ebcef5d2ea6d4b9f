"""How the Supervisor finds faults and survives them: a lost or unseated part picked again from
where it lies, a path blocked by an obstacle waited out, a protective stop and an operator's
silence noted (each a `Detection`); and, when the robot cannot do the task but is itself sound,
the task handed over to the operator, who does it by hand while the arm holds still, after
which the assembly goes on.

`FaultRecovery` is a part of `hrc_drake.cell.controller.supervisor.Supervisor`: it takes the
status and the update's `Readings` and returns the next status; it asks the planner through the
`PlanAsker` it is given, and keeps its own record, `RecoveryState`, in the status. This module
is the one writer of that record, of the `Detection`s and of how a run ended (`error`,
`capped`); the arm, the question and the turn it changes through their owners' functions.
"""

from __future__ import annotations

from dataclasses import replace

from hrc_drake.cell.controller import question
from hrc_drake.cell.controller.anticipation import Turn, cancelled, turn_at, turn_to
from hrc_drake.cell.controller.follower import back_off, hold
from hrc_drake.cell.controller.guard import GuardTrip, Retreat, tau_at_height
from hrc_drake.cell.controller.planning import PlanAsker
from hrc_drake.cell.controller.readings import Readings
from hrc_drake.cell.controller.supervisor_state import (
    GRIP_SETTLE,
    PART_FALL_TIME,
    TASK_CAP,
    Cause,
    Detection,
    Event,
    Mode,
    Recovery,
    SupervisorError,
    SupervisorLimits,
    SupervisorStatus,
    obstacle_moved,
)
from hrc_drake.cell.ports import CellConfiguration, PartStatus, SafetyMode
from hrc_drake.hri.messages import Prompt, PromptKind
from hrc_drake.motion.plan import Stage
from hrc_drake.motion.plan_request import PlanFailure, PlanRequest
from hrc_drake.tasks.assembly import AssemblySpec


class FaultRecovery:
    """The Supervisor's fault handling (see the module docstring): `limits` are the run's
    timeouts, tolerances and tries, `home` the arm's home posture."""

    def __init__(
        self,
        limits: SupervisorLimits,
        spec: AssemblySpec,
        asker: PlanAsker,
        home: tuple[float, ...],
    ):
        self._limits, self._spec, self._asker, self._home = limits, spec, asker, home

    def check_grip(self, s: SupervisorStatus, cell: Readings, now: float) -> SupervisorStatus:
        """Between the grasp and the release the fingers must stand at the part's width,
        stalled on it (closed past it, the gripper holds nothing); from the release's end they
        must have left it (standing at it, the gripper does not open; the arm waits there
        meanwhile, `release_wait`)."""
        plan, tau = s.plan, s.plan_time(now)
        opening = cell.opening()
        width = plan.grip_width
        if plan.segment(Stage.GRASP).end + GRIP_SETTLE <= tau < plan.t_release:
            gripped = cell.gripped()
            ok = gripped and abs(opening - width) <= self._limits.grip_tolerance
            cause, what = (
                Cause.GRIP,
                (
                    f"({'stalled' if gripped else 'no grip detected'}) where {plan.instance} is "
                    f"{width * 1000:.1f} mm wide: it does not hold the part"
                ),
            )
        elif plan.segment(Stage.RELEASE).end <= tau < plan.duration:
            ok = self._let_go(plan, opening)
            cause, what = (
                Cause.RELEASE,
                (
                    f"after the release, on {plan.instance} ({width * 1000:.1f} mm): the gripper "
                    "does not open and may still hold the part"
                ),
            )
        else:
            return self._grip_lost_at(s, None)
        if ok:
            return self._grip_lost_at(s, None)
        lost_at = s.recovery.grip_lost_at
        if lost_at is None or now - lost_at < GRIP_SETTLE:
            return self._grip_lost_at(s, now if lost_at is None else lost_at)
        # Closed past the part's width (to the command's squeeze): nothing between the fingers.
        slipped = cause == Cause.GRIP and opening < width
        recoveries = s.recovery.recoveries
        if slipped and recoveries < self._limits.recover_tries:
            return self.lose_part(s, cell, now, Cause.GRIP, Recovery.REGRASP)
        if slipped:  # it keeps slipping: the part is out of the gripper, the operator seats it
            times = recoveries + 1
            raise SupervisorError(
                f"step {s.step}: {plan.instance} slipped out of the gripper "
                f"{times} time{'s' if times > 1 else ''}; the task is handed over",
                cause=cause,
                hand_over=True,
            )
        raise SupervisorError(
            f"step {s.step}: the gripper stands at {opening * 1000:.1f} mm {what}; the task is "
            "stopped",
            cause=cause,
        )

    def release_wait(self, s: SupervisorStatus, tau: float, opening: float) -> float | None:
        """The plan time where the arm waits after a release while its fingers, at the measured
        `opening`, have not yet left the part (None: no wait). It goes on only once they have,
        as a robot program waits for its gripper's report before it moves off: fingers that
        stay on a bolted part would drag it (`check_grip` stops the task meanwhile)."""
        plan = s.plan
        end = plan.segment(Stage.RELEASE).end
        return end if end <= tau < plan.duration and not self._let_go(plan, opening) else None

    def _let_go(self, plan, opening: float) -> bool:
        """Whether fingers at `opening` have left `plan`'s part."""
        return opening > plan.grip_width + 2 * self._limits.grip_tolerance

    def stop_pressing(self, s: SupervisorStatus, trip: GuardTrip, now: float) -> SupervisorStatus:
        """The guarded descent tripped (`trip`): the part met something before its seat. Stop
        pressing — the arm backs off to where it stood just before the contact — and let the
        part go there (the fingers open as at a release, for `gripper_time`); then the arm goes
        back up its own descent to the pre-place pose (a `Retreat`, as long as the descent
        took from there), and the cell is read once the part settles, as after any release: a
        part out of its seat is picked again and re-placed, or the task handed over
        (`Supervisor._observe`). The plan's hold for the bolts never came: the arm holds away
        from home, and the next plan starts where it holds."""
        plan, part, limits = s.plan, s.task.part, self._limits
        place = plan.segment(Stage.PLACE)
        tau_from = tau_at_height(plan, trip.above_back, limits.guard.descent)
        start = now + limits.gripper_time
        end = start + 1.5 * (tau_from - place.start)  # unhurried: the descent's own pace
        retreat = Retreat(plan, trip.q_back, tau_from, place.start, start, end)
        event = (
            f"{now:.2f}: guarded descent: {part} meets something {trip.above * 1000:.1f} mm "
            f"above its place ({trip.rise:.0f} N against the approach): stops pressing, backs "
            "off and lets it go"
        )
        q = tuple(float(x) for x in plan.positions(place.start))
        s = back_off(s, retreat, q, plan.gripper_opening(plan.segment(Stage.RELEASE).end))
        s = question.withdrawn(s.noted(event).enter(Event.GUARD_TRIPPED, end + limits.settle_time))
        return replace(s, recovery=replace(s.recovery, guarded=True, away=True, grip_lost_at=None))

    @staticmethod
    def _grip_lost_at(s: SupervisorStatus, at: float | None) -> SupervisorStatus:
        if s.recovery.grip_lost_at == at:
            return s  # as it was (asked every update): no copy of the status
        return replace(s, recovery=replace(s.recovery, grip_lost_at=at))

    def lose_part(
        self, s: SupervisorStatus, cell: Readings, now: float, cause: Cause, recovery: Recovery
    ) -> SupervisorStatus:
        """The task's part is out of the gripper where it should not be (slipped during the
        carry, or let go out of its seat): hold the arm where it is measured (a part wedged
        against it must not be pushed into), open the fingers a little (to let go of anything
        caught between them), withdraw a `BOLT` prompt (nobody should reach in to bolt now),
        and let the part come to rest before it is picked again from where it lies."""
        part = s.task.part
        q = cell.arm_q()
        wait = PART_FALL_TIME if cause == Cause.GRIP else 0.0
        what = "is not in the gripper" if cause == Cause.GRIP else "does not sit in its seat"
        event = f"{now:.2f}: {part} {what}: {recovery} once it rests"
        s = s.noted(event).enter(Event.PART_LOST, now + max(wait, self._limits.settle_time))
        s = question.withdrawn(hold(s, tuple(float(x) for x in q), cell.opening() + 0.02))
        record = replace(
            s.recovery,
            recovering=recovery,
            recoveries=s.recovery.recoveries + 1,
            grip_lost_at=None,
        )
        found = Detection(cause, s.step, now)
        return replace(s, recovery=record, detections=(*s.detections, found))

    def pick_again(
        self, s: SupervisorStatus, config: CellConfiguration, now: float
    ) -> SupervisorStatus:
        """Ask the planner to pick the task's part from where the configuration sensor reads
        it and place it where the operator indicated, starting from where the arm holds."""
        indicated, part = s.task.indicated, s.task.part
        placement = config.placement(part)
        if not placement.pose or placement.status == PartStatus.HELD:
            raise SupervisorError(f"step {s.step}: {part} cannot be found", cause=Cause.GRIP)
        layout = {i: t for i, t in config.layout().items() if i != part}
        if frozenset(layout.values()) != s.tokens_before:
            raise SupervisorError(
                f"step {s.step}: while {part} was out of the gripper the cell changed to "
                f"{sorted(layout.values())}; the task is handed over",
                cause=Cause.CONFIGURATION,
            )
        last = s.state[-1] if s.state else None
        request = PlanRequest.of(
            s.tokens_before,
            indicated,
            last,
            layout,
            instance=part,
            source_pose=tuple(placement.pose),
            start=s.q_hold,
            obstacle=config.obstacle,
            start_opening=s.opening_hold,
        )
        event = f"{now:.2f}: plans to pick {part} from where it lies ({placement.status.value})"
        return self._asker.ask(s.noted(event), request, now)

    def blocked(self, s: SupervisorStatus, failure: PlanFailure, now: float) -> SupervisorStatus:
        """No path while an obstacle is in the cell: hold still and wait for it to move."""
        if s.open_detection(Cause.PLAN):
            return s.enter(Event.PATH_BLOCKED)  # planned again, still blocked
        event = f"{now:.2f}: step {s.step}: an obstacle blocks the path ({failure.reason}); waits"
        return replace(
            s.noted(event).enter(Event.PATH_BLOCKED),
            recovery=replace(s.recovery, blocked_at=now),
            detections=(*s.detections, Detection(Cause.PLAN, s.step, now)),
        )

    def wait_for_path(
        self, s: SupervisorStatus, config: CellConfiguration, now: float
    ) -> SupervisorStatus:
        """Plan again once the obstacle has moved or gone; hand over after `path_timeout`."""
        timeout = self._limits.path_timeout
        if now - s.recovery.blocked_at > timeout:
            raise SupervisorError(
                f"step {s.step}: an obstacle has blocked the path for {timeout:g} s "
                "(run.path_timeout): clear the cell; the task is handed over",
                cause=Cause.PLAN,
                hand_over=True,
            )
        request = s.ask.request
        if not obstacle_moved(request.obstacle, config.obstacle):
            return s
        request = replace(request, obstacle=config.obstacle or None)
        event = f"{now:.2f}: the obstacle " + ("moved" if config.obstacle else "is gone")
        return self._asker.ask(s.noted(f"{event}: plans again"), request, now)

    def watch_obstacle(
        self, s: SupervisorStatus, config: CellConfiguration, now: float
    ) -> SupervisorStatus:
        """An obstacle seen that the plan did not know (it came after the plan was made): stop
        on the path and plan the task again from there (a turn to the same task)."""
        if not config.obstacle or not obstacle_moved(s.ask.request.obstacle, config.obstacle):
            return s
        task, tau = s.task.indicated, s.plan_time(now)
        if turn_at(s.plan, tau, self._spec, task) == Turn.TOO_LATE:
            return s  # placing: the part is where it goes
        event = f"{now:.2f}: an obstacle appears: stops to plan {task} again"
        return turn_to(s.noted(event), task)

    def note_stop(
        self, s: SupervisorStatus, stop: bool, now: float, mode: SafetyMode
    ) -> SupervisorStatus:
        """Note the robot's safety system stopping the arm (the plan stops on its path) and
        letting it go (it resumes where it stopped, the task state untouched). A protective
        stop is a fault found (a `Detection`); a safeguard stop clears by itself, and the
        controller, which reads only the safety mode as a UR reports it, does not name its cause
        (the separation, or commands that stopped coming: the station's run log says which)."""
        if stop == s.recovery.stopped or s.mode in (Mode.DONE, Mode.FAILED):
            return s
        if stop and mode == SafetyMode.SAFEGUARD_STOP:
            event = f"{now:.2f}: safeguard stop: the robot stops on its path until it clears"
            return replace(s.noted(event), recovery=replace(s.recovery, stopped=True))
        if stop:
            event = f"{now:.2f}: protective stop: the robot stops on its path"
            found = Detection(Cause.STOP, s.step, now)
            return replace(
                s.noted(event),
                recovery=replace(s.recovery, stopped=True),
                detections=(*s.detections, found),
            )
        s = s.noted(f"{now:.2f}: stop cleared: resumes")
        s = replace(s, recovery=replace(s.recovery, stopped=False))
        return resolve(s, Cause.STOP, now, Recovery.RESUME)

    def note_silence(self, s: SupervisorStatus, now: float) -> SupervisorStatus:
        """No answer within the timeout: the robot holds still where it is and asks again (the
        same prompt, its `asked` count one up, so that an interface shows it afresh; the wait
        starts over). No answer `indication_give_up` seconds after the question was first
        asked: SupervisorError, the run stops (a question nobody answers, or whose answer was
        lost, never leaves a run looping)."""
        give_up = self._limits.indication_give_up
        up = s.question
        what = "confirmation" if up.prompt.kind == PromptKind.HANDOVER else "indication"
        if now - up.prompted_at >= give_up:
            asked = up.prompt.asked + 1
            raise SupervisorError(
                f"step {s.step}: no {what} from the operator in {give_up:g} s of simulated "
                f"time (asked {asked} time{'s' if asked > 1 else ''}; run.indication_give_up): "
                "the run stops",
                cause=Cause.SILENCE,
            )
        timeout = self._limits.indication_timeout
        if now - up.asked_at < timeout:
            return s
        event = f"{now:.2f}: no {what} for step {s.step} in {timeout:g} s: asks again"
        found = Detection(Cause.SILENCE, s.step, now)
        detections = s.detections if s.open_detection(Cause.SILENCE) else (*s.detections, found)
        return replace(question.asked_again(s.noted(event), now), detections=detections)

    def stop(
        self, s: SupervisorStatus, cell: Readings, now: float, err: SupervisorError
    ) -> SupervisorStatus:
        """Stop the task: the arm holds where it is measured, the gripper keeps its command
        (a part in it stays held)."""
        q = cell.arm_q()
        opening = s.command(now).opening
        if err.cause == TASK_CAP:
            s = replace(s, capped=True)
        elif not s.open_detection():
            s = replace(s, detections=(*s.detections, Detection(err.cause, s.step, now)))
        s = resolve(s, None, now, Recovery.OPERATOR)
        s = replace(s.noted(f"{now:.2f}: stopped: {err}").enter(Event.STOPPED), error=str(err))
        return hold(s, tuple(float(x) for x in q), float(opening))

    def hand_over(
        self, s: SupervisorStatus, cell: Readings, now: float, err: SupervisorError
    ) -> SupervisorStatus:
        """The robot cannot do the task (`err`) but is itself sound: the arm holds where it is
        measured, the fingers keep their command (open: the part is out of them), and the
        interface asks the operator to do the task by hand (`HANDOVER`: the task, its part if
        the robot chose one, and why). A task the operator already did, or a step with no task,
        is not handed over again: the run stops (`stop`)."""
        if s.recovery.handover or s.task is None or s.mode in (Mode.DONE, Mode.FAILED):
            return self.stop(s, cell, now, err)
        indicated, part = s.task.indicated, s.task.part
        q = cell.arm_q()
        opening = float(s.command(now).opening)
        if not s.open_detection():
            s = replace(s, detections=(*s.detections, Detection(err.cause, s.step, now)))
        reason = str(err)
        prompt = Prompt(s.step, PromptKind.HANDOVER, s.state, indicated, part, reason=reason)
        event = f"{now:.2f}: hands {indicated} over to the operator: {reason}"
        home = max(abs(a - b) for a, b in zip(q, self._home, strict=True)) < 1e-3
        s = cancelled(s.noted(event).enter(Event.HANDED_OVER))
        s = question.handed_over(hold(s, tuple(float(x) for x in q), opening), prompt, now)
        record = replace(s.recovery, handover=reason, away=not home, grip_lost_at=None)
        return replace(s, recovery=record)

    def wait_for_operator(
        self, s: SupervisorStatus, cell: Readings, now: float
    ) -> SupervisorStatus:
        """Handed over: hold still until the operator says the task is done (asking again
        while they are silent, giving up as for an indication); then let the parts settle and
        read the cell as after any task."""
        if not cell.indication().answers(s.question.prompt):
            return self.note_silence(s, now)
        s = resolve(s, None, now, Recovery.OPERATOR)
        event = f"{now:.2f}: the operator has done {s.task.indicated} by hand"
        s = s.noted(event).enter(Event.DONE_BY_HAND, now + self._limits.settle_time)
        return replace(question.cleared(s), recovery=replace(s.recovery, recovering=None))


def resolve(s: SupervisorStatus, cause: Cause | None, now: float, recovery: Recovery):
    """`s` with its open detections of `cause` (None: every cause) marked recovered by
    `recovery` at `now`."""
    detections = tuple(
        replace(d, resolved_at=now, recovery=recovery)
        if cause in (None, d.cause) and d.resolved_at is None
        else d
        for d in s.detections
    )
    return replace(s, detections=detections)


def plan_started(s: SupervisorStatus) -> SupervisorStatus:
    """`s` starting on a plan: every plan ends at home, so the arm is no longer away."""
    return replace(s, recovery=replace(s.recovery, away=False))


def settled(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with the parts settled after a guarded stop (the cell is read as after any task)."""
    return replace(s, recovery=replace(s.recovery, guarded=False))


def task_closed(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with its task read from the cell: nothing picked again or handed over any more."""
    record = replace(s.recovery, recovering=None, recoveries=0, handover="")
    return replace(s, recovery=record)


__all__ = ["FaultRecovery", "plan_started", "resolve", "settled", "task_closed"]
