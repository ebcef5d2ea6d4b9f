"""How the Supervisor finds faults and survives them: a lost or unseated part picked again from
where it lies, a path blocked by an obstacle waited out, a protective stop and an operator's
silence noted (each a `Detection`); and, when the robot cannot do the task but is itself sound,
the task handed over to the operator, who does it by hand while the arm holds still, after
which the assembly goes on. A mixin of `hrc_drake.cell.controller.supervisor.Supervisor`: it uses
the Supervisor's ports (`_arm_port`, `_gripper_port`, `_grip_port`), its `_ask` of the
planner, limits (`_limits`) and task space (`_space`).
"""

from __future__ import annotations

from dataclasses import replace

from hrc_drake.cell.controller.anticipation import Turn, turn_at
from hrc_drake.cell.controller.supervisor_state import (
    GRIP_SETTLE,
    N_JOINTS,
    PART_FALL_TIME,
    Detection,
    Mode,
    SupervisorError,
    SupervisorStatus,
    obstacle_moved,
)
from hrc_drake.cell.ports import CellConfiguration, PartStatus
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.motion.plan import Stage
from hrc_drake.motion.plan_request import PlanFailure, PlanRequest


class FaultRecovery:
    """The Supervisor's fault handling (see the module docstring)."""

    def _check_grip(self, s: SupervisorStatus, context, now: float) -> SupervisorStatus:
        """Between the grasp and the release the fingers must stand at the part's width,
        stalled on it (closed past it, the gripper holds nothing); after the release they must
        have left it (standing at it, the gripper does not open)."""
        plan, tau = s.plan, s.plan_time(now)
        opening = float(self._gripper_port.Eval(context)[0])
        width = plan.grip_width
        if plan.segment(Stage.GRASP).end + GRIP_SETTLE <= tau < plan.t_release:
            gripped = self._grip_port.Eval(context)[0] > 0.5
            ok = gripped and abs(opening - width) <= self._limits.grip_tolerance
            cause, what = (
                "grip",
                (
                    f"({'stalled' if gripped else 'no grip detected'}) where {plan.instance} is "
                    f"{width * 1000:.1f} mm wide: it does not hold the part"
                ),
            )
        elif plan.segment(Stage.RELEASE).end + GRIP_SETTLE <= tau < plan.duration:
            ok = opening > width + 2 * self._limits.grip_tolerance
            cause, what = (
                "release",
                (
                    f"after the release, on {plan.instance} ({width * 1000:.1f} mm): the gripper "
                    "does not open and may still hold the part"
                ),
            )
        else:
            return replace(s, grip_lost_at=None)
        if ok:
            return replace(s, grip_lost_at=None)
        if s.grip_lost_at is None or now - s.grip_lost_at < GRIP_SETTLE:
            return replace(s, grip_lost_at=now if s.grip_lost_at is None else s.grip_lost_at)
        # Closed past the part's width (to the command's squeeze): nothing between the fingers.
        slipped = cause == "grip" and opening < width
        if slipped and s.recoveries < self._limits.recover_tries:
            return self._lose_part(s, context, now, "grip", "regrasp")
        if slipped:  # it keeps slipping: the part is out of the gripper, the operator seats it
            times = s.recoveries + 1
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

    def _lose_part(self, s: SupervisorStatus, context, now: float, cause: str, recovery: str):
        """The task's part is out of the gripper where it should not be (slipped during the
        carry, or let go out of its seat): hold the arm where it is measured (a part wedged
        against it must not be pushed into), open the fingers a little (to let go of anything
        caught between them), withdraw a `BOLT` prompt (nobody should reach
        in to bolt now), and let the part come to rest before it is picked again from where it
        lies."""
        part = s.pending[2]
        q = self._arm_port.Eval(context)[:N_JOINTS]
        wait = PART_FALL_TIME if cause == "grip" else 0.0
        what = "is not in the gripper" if cause == "grip" else "does not sit in its seat"
        event = f"{now:.2f}: {part} {what}: {recovery} once it rests"
        return replace(
            s,
            mode=Mode.RECOVER,
            plan=None,
            q_hold=tuple(float(x) for x in q),
            opening_hold=float(self._gripper_port.Eval(context)[0]) + 0.02,
            settle_until=now + max(wait, self._limits.settle_time),
            recovering=recovery,
            recoveries=s.recoveries + 1,
            grip_lost_at=None,
            # A question still open (anticipating, the indication not in yet) stays up: withdrawn,
            # it could never be answered and the robot would wait for it forever.
            prompt=s.prompt
            if s.prompt.kind == PromptKind.CHOOSE
            else replace(s.prompt, kind=PromptKind.NONE),
            detections=(*s.detections, Detection(cause, s.step, now)),
            events=(*s.events, event),
        )

    def _pick_again(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """Ask the planner to pick the task's part from where the configuration sensor reads
        it and place it where the operator indicated, starting from where the arm holds."""
        _proposed, indicated, part = s.pending
        placement = config.placement(part)
        if not placement.pose or placement.status == PartStatus.HELD:
            raise SupervisorError(f"step {s.step}: {part} cannot be found", cause="grip")
        layout = {i: t for i, t in config.layout().items() if i != part}
        if frozenset(layout.values()) != s.tokens_before:
            raise SupervisorError(
                f"step {s.step}: while {part} was out of the gripper the cell changed to "
                f"{sorted(layout.values())}; the task is handed over",
                cause="configuration",
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
        return self._ask(s, request, now, events=(*s.events, event))

    def _blocked(self, s: SupervisorStatus, failure: PlanFailure, now: float):
        """No path while an obstacle is in the cell: hold still and wait for it to move."""
        if s.open_detection("plan"):
            return replace(s, mode=Mode.BLOCKED)  # planned again, still blocked
        event = f"{now:.2f}: step {s.step}: an obstacle blocks the path ({failure.reason}); waits"
        return replace(
            s,
            mode=Mode.BLOCKED,
            blocked_at=now,
            detections=(*s.detections, Detection("plan", s.step, now)),
            events=(*s.events, event),
        )

    def _wait_for_path(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """Plan again once the obstacle has moved or gone; hand over after `path_timeout`."""
        timeout = self._limits.path_timeout
        if now - s.blocked_at > timeout:
            raise SupervisorError(
                f"step {s.step}: an obstacle has blocked the path for {timeout:g} s "
                "(run.path_timeout): clear the cell; the task is handed over",
                cause="plan",
                hand_over=True,
            )
        if not obstacle_moved(s.request.obstacle, config.obstacle):
            return s
        request = replace(s.request, obstacle=config.obstacle or None)
        event = f"{now:.2f}: the obstacle " + ("moved" if config.obstacle else "is gone")
        return self._ask(s, request, now, events=(*s.events, f"{event}: plans again"))

    def _watch_obstacle(self, s: SupervisorStatus, config: CellConfiguration, now: float):
        """An obstacle seen that the plan did not know (it came after the plan was made): stop
        on the path and plan the task again from there (`_turn` to the same task)."""
        if not config.obstacle or not obstacle_moved(s.request.obstacle, config.obstacle):
            return s
        task, tau = s.pending[1], s.plan_time(now)
        if turn_at(s.plan, tau, self._space.spec, task) == Turn.TOO_LATE:
            return s  # placing: the part is where it goes
        event = f"{now:.2f}: an obstacle appears: stops to plan {task} again"
        return replace(s, change=task, events=(*s.events, event))

    def _note_stop(self, s: SupervisorStatus, stop: bool, now: float) -> SupervisorStatus:
        """Note the protective-stop input turning on (the robot stops on its path) and off
        (it resumes where it stopped, the task state untouched)."""
        if stop == s.stopped or s.mode in (Mode.DONE, Mode.FAILED):
            return s
        if stop:
            event = f"{now:.2f}: protective stop: the robot stops on its path"
            found = Detection("stop", s.step, now)
            return replace(
                s, stopped=True, detections=(*s.detections, found), events=(*s.events, event)
            )
        s = replace(s, stopped=False, events=(*s.events, f"{now:.2f}: stop cleared: resumes"))
        return self._resolve(s, "stop", now, "resume")

    def _note_silence(self, s: SupervisorStatus, now: float) -> SupervisorStatus:
        """No answer within the timeout: the robot holds still where it is and asks again (the
        same prompt, its `asked` count one up, so that an interface shows it afresh; the wait
        starts over). No answer `indication_give_up` seconds after the question was first
        asked: SupervisorError, the run stops (a question nobody answers, or whose answer was
        lost, never leaves a run looping)."""
        give_up = self._limits.indication_give_up
        what = "confirmation" if s.prompt.kind == PromptKind.HANDOVER else "indication"
        if now - s.prompted_at >= give_up:
            asked = s.prompt.asked + 1
            raise SupervisorError(
                f"step {s.step}: no {what} from the operator in {give_up:g} s of simulated "
                f"time (asked {asked} time{'s' if asked > 1 else ''}; run.indication_give_up): "
                "the run stops",
                cause="silence",
            )
        timeout = self._limits.indication_timeout
        if now - s.asked_at < timeout:
            return s
        event = f"{now:.2f}: no {what} for step {s.step} in {timeout:g} s: asks again"
        found = Detection("silence", s.step, now)
        detections = s.detections if s.open_detection("silence") else (*s.detections, found)
        prompt = replace(s.prompt, asked=s.prompt.asked + 1)
        return replace(
            s, asked_at=now, prompt=prompt, detections=detections, events=(*s.events, event)
        )

    def _hand_over(self, s: SupervisorStatus, context, now: float, err: SupervisorError):
        """The robot cannot do the task (`err`) but is itself sound: the arm holds where it is
        measured, the fingers keep their command (open: the part is out of them), and the
        interface asks the operator to do the task by hand (`HANDOVER`: the task, its part if
        the robot chose one, and why). A task the operator already did, or a step with no task,
        is not handed over again: the run stops (`_stop`)."""
        if s.handover or s.pending is None or s.mode in (Mode.DONE, Mode.FAILED):
            return self._stop(s, context, now, err)
        _proposed, indicated, part = s.pending
        q = self._arm_port.Eval(context)[:N_JOINTS]
        if not s.open_detection():
            s = replace(s, detections=(*s.detections, Detection(err.cause, s.step, now)))
        reason = str(err)
        prompt = Prompt(s.step, PromptKind.HANDOVER, s.state, indicated, part, reason=reason)
        event = f"{now:.2f}: hands {indicated} over to the operator: {reason}"
        home = max(abs(a - b) for a, b in zip(q, self._home, strict=True)) < 1e-3
        return replace(
            s,
            mode=Mode.HANDOVER,
            plan=None,
            change=None,
            awaiting=False,
            q_hold=tuple(float(x) for x in q),
            opening_hold=float(s.command(now)[2]),
            prompt=prompt,
            handover=reason,
            away=not home,
            asked_at=now,
            prompted_at=now,
            grip_lost_at=None,
            events=(*s.events, event),
        )

    def _wait_for_operator(self, s: SupervisorStatus, context, now: float):
        """Handed over: hold still until the operator says the task is done (asking again
        while they are silent, giving up as for an indication); then let the parts settle and
        read the cell as after any task (`_observe`)."""
        indication: Indication = self._indication_port.Eval(context)
        if not indication.answers(s.prompt):
            return self._note_silence(s, now)
        s = self._resolve(s, None, now, "operator")
        event = f"{now:.2f}: the operator has done {s.pending[1]} by hand"
        return replace(
            s,
            mode=Mode.SETTLE,
            settle_until=now + self._limits.settle_time,
            prompt=replace(s.prompt, kind=PromptKind.NONE),
            recovering="",
            events=(*s.events, event),
        )

    @staticmethod
    def _resolve(s: SupervisorStatus, cause: str | None, now: float, recovery: str):
        """Mark the open detections of `cause` (None: every cause) recovered by `recovery` at
        `now`."""
        detections = tuple(
            replace(d, resolved_at=now, recovery=recovery)
            if cause in (None, d.cause) and d.resolved_at is None
            else d
            for d in s.detections
        )
        return replace(s, detections=detections)


__all__ = ["FaultRecovery"]
