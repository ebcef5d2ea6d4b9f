"""The simulated operator inside the station: answers the interface's prompts and bolts parts.

On a real cell a person reads the interface, points at a target, bolts the part the robot holds
and says so. In the simulated station `SimulatedOperator` does that: it hands each `CHOOSE`
prompt to an operator model (a script, a population model: any `hrc_drake.tasks.decide.Operator`
callable; or a person clicking in the browser, asked without blocking at every update, so the
robot moves while they choose) and publishes the answer as an `Indication`,
after the operator's `indication_delay(step)` when it has one (the interface's delay);
on a `BOLT` prompt it bolts the held part for `bolt_time` seconds (its body reaches in, see
`hrc_drake.cell.station.operator_body`) and says it is bolted; the bolts take once the robot has let
the part go and it rests (`resting`) where the configuration sensor reads it in a seat, and
fix it where it sits then, not at the nominal seat (`hrc_drake.cell.station.welds`): a part released
settles in its pocket under contact first. Before an undo it takes the bolts out of the part
that goes back. On a `HANDOVER` prompt it does the task by hand: it takes `handover_time`
seconds to fetch the part and put it in its seat, then bolts it (`bolt_time`) and says it is
done (a person in the browser clicks "I did ..." instead, in their own time); the station then
puts the part in its seat (`placements`, applied by `CellStation.apply_welds`, as the welds
are) and the bolt takes once it rests there.

What it does is its `activity` output (for the body) and its `bolts` output (the bolt welds the
station applies: simulator only). The controller sees none of this: only `hri.indication`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from hrc_drake.cell.ports import ActivityKind, CellConfiguration, OperatorActivity, PartStatus
from hrc_drake.cell.station.welds import Weld
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.tasks.decide import Operator
from hrc_drake.tasks.protocols import AskedWithoutBlocking, DelaysIndications, TiresAlongTheRun
from hrc_drake.tasks.tokens import UNDO


def bolt_weld(configuration: CellConfiguration, part: str) -> Weld | None:
    """The bolt weld that fixes `part` in the seat the configuration reads it in (None if it is
    in no seat: the operator cannot bolt it)."""
    placement = configuration.placement(part)
    if placement.status != PartStatus.SEATED or not placement.seats:
        return None
    if placement.host is None:
        return Weld(part, placement.token or "")
    return Weld(part, f"{placement.host}/{placement.seats[0]}")


class SimulatedOperator(LeafSystem):
    """The operator of the simulated station (see the module docstring).

    Input ports: `hri.prompt` (Prompt), `configuration` (CellConfiguration), `resting`
    (frozenset of the parts at rest and out of the gripper; unconnected: all). Output ports:
    `hri.indication` (Indication), `activity` (OperatorActivity), `bolts` (frozenset[Weld]).
    Updated every `period` seconds. `handover_time`: seconds a task handed over takes by hand
    before its bolting."""

    def __init__(
        self,
        operator: Operator,
        bolt_time: float,
        period: float,
        busy_until: Callable[[OperatorActivity], float] | None = None,
        handover_time: float = 5.0,
    ):
        super().__init__()
        self._operator, self._bolt_time = operator, bolt_time
        self._handover_time = handover_time
        # When the hands are free to bolt (an operator still fetching bolts starts after).
        self._busy_until = busy_until
        self._prompt = self.DeclareAbstractInputPort("hri.prompt", AbstractValue.Make(Prompt()))
        self._configuration = self.DeclareAbstractInputPort(
            "configuration", AbstractValue.Make(CellConfiguration())
        )
        # The parts at rest and out of the gripper (unconnected: every part).
        self._resting = self.DeclareAbstractInputPort("resting", AbstractValue.Make(frozenset()))
        self._indication = self.DeclareAbstractState(AbstractValue.Make(Indication()))
        self._activity = self.DeclareAbstractState(AbstractValue.Make(OperatorActivity()))
        self._bolts = self.DeclareAbstractState(AbstractValue.Make(frozenset()))
        # Parts bolted that do not rest in a seat yet: the bolts take when they do.
        self._pending = self.DeclareAbstractState(AbstractValue.Make(frozenset()))
        # (step, time) the indication of the step is due: the prompt seen plus the delay.
        self._asked = self.DeclareAbstractState(AbstractValue.Make((0, 0.0)))
        # A task handed over: (step, when it is done by hand); and the placements done by hand
        # that the station has still to make, (task, part or "", state) each.
        self._by_hand = self.DeclareAbstractState(AbstractValue.Make((0, 0.0)))
        self._placements = self.DeclareAbstractState(AbstractValue.Make(()))
        self.DeclareStateOutputPort("hri.indication", self._indication)
        self.DeclareStateOutputPort("activity", self._activity)
        self.DeclareStateOutputPort("bolts", self._bolts)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def _update(self, context, state) -> None:
        prompt: Prompt = self._prompt.Eval(context)
        now = context.get_time()
        indication = context.get_abstract_state(self._indication).get_value()
        activity = context.get_abstract_state(self._activity).get_value()
        bolts = context.get_abstract_state(self._bolts).get_value()
        pending = context.get_abstract_state(self._pending).get_value()
        task = None
        if (
            prompt.kind == PromptKind.CHOOSE
            and indication.step < prompt.step
            and now >= self._due(context, state, prompt.step, now)
        ):
            task = self._answer(prompt)
        if task is not None:
            indication = Indication(prompt.step, task, False, now)
            activity = replace(
                activity, answered_step=prompt.step, answered_at=now, answered_task=task
            )
            if task == UNDO and prompt.state:
                parts = self._parts_at(context, prompt.state[-1])
                bolts = frozenset(w for w in bolts if w.part not in parts)
                pending = pending - parts
        elif prompt.kind == PromptKind.BOLT and prompt.step == indication.step:
            if not indication.bolted and activity.kind != ActivityKind.BOLT:
                free = now if self._busy_until is None else self._busy_until(activity)
                activity = replace(
                    activity,
                    kind=ActivityKind.BOLT,
                    part=prompt.part,
                    start=max(now, free),
                    duration=self._bolting(prompt.step),
                    step=prompt.step,
                )
            elif activity.kind == ActivityKind.BOLT and now >= activity.start + activity.duration:
                pending = pending | {activity.part}
                indication = replace(indication, bolted=True, time=now)
                activity = replace(activity, kind=ActivityKind.REST)
        elif prompt.kind == PromptKind.HANDOVER and not (
            indication.step == prompt.step and indication.done
        ):
            indication, activity = self._do_by_hand(context, state, prompt, indication, activity)
        elif activity.kind == ActivityKind.BOLT and not indication.bolted:
            # The robot withdrew its prompt (it lost the part): hands off, back to rest.
            activity = replace(activity, kind=ActivityKind.REST)
        bolts, pending = self._seat_bolts(context, bolts, pending)
        state.get_mutable_abstract_state(self._indication).set_value(indication)
        state.get_mutable_abstract_state(self._activity).set_value(activity)
        state.get_mutable_abstract_state(self._bolts).set_value(bolts)
        state.get_mutable_abstract_state(self._pending).set_value(pending)

    def _do_by_hand(self, context, state, prompt: Prompt, indication, activity):
        """A task handed over: (indication, activity). The simulated operator reaches in for
        `handover_time` plus the bolting time, then says it is done; a person in the browser
        (an operator asked without blocking, `poll`) says so with a click. Done, the placement
        goes to the station (`placements`)."""
        now = context.get_time()
        if isinstance(self._operator, AskedWithoutBlocking):
            done = self._operator.poll(prompt) is not None
        else:
            step, due = context.get_abstract_state(self._by_hand).get_value()
            if step != prompt.step:
                due = now + self._handover_time + self._bolting(prompt.step)
                state.get_mutable_abstract_state(self._by_hand).set_value((prompt.step, due))
                activity = replace(
                    activity,
                    kind=ActivityKind.BOLT,  # the hands in the cell, at the part
                    part=prompt.part,
                    start=now,
                    duration=due - now,
                    step=prompt.step,
                )
            done = now >= due
        if not done:
            return indication, activity
        placements = context.get_abstract_state(self._placements).get_value()
        placement = (prompt.proposal, prompt.part, prompt.state)
        state.get_mutable_abstract_state(self._placements).set_value((*placements, placement))
        indication = Indication(prompt.step, prompt.proposal, True, now, done=True)
        return indication, replace(activity, kind=ActivityKind.REST)

    def _bolting(self, step: int) -> float:
        """Seconds the operator bolts at decision `step`: `bolt_time`, scaled by the operator
        model's `bolt_scale(step)` when it has one (the `slow` population tires along the run;
        the robot holds the part until the operator says it is bolted)."""
        if not isinstance(self._operator, TiresAlongTheRun):
            return self._bolt_time
        return self._bolt_time * float(self._operator.bolt_scale(step))

    def placements(self, context) -> tuple[tuple[str, str, tuple[str, ...]], ...]:
        """Sim only: the tasks done by hand whose part the station has still to put in place,
        (task, part instance or "" for any free one, the MDP state before) each."""
        return context.get_abstract_state(self._placements).get_value()

    def placed(self, context, part: str) -> None:
        """Sim only: the station has put `part` in place for a task done by hand (the oldest
        of `placements`); its bolt takes once it rests in its seat. `context` is this system's
        mutable context."""
        placements = context.get_abstract_state(self._placements).get_value()
        context.get_mutable_abstract_state(self._placements).set_value(placements[1:])
        if part:
            pending = context.get_abstract_state(self._pending).get_value()
            context.get_mutable_abstract_state(self._pending).set_value(pending | {part})

    def _answer(self, prompt: Prompt) -> str | None:
        """The operator's answer to a `CHOOSE` prompt: at once from an operator callable, or,
        from one that is asked without blocking (`poll`: a person clicking in the browser),
        None until it has one."""
        if isinstance(self._operator, AskedWithoutBlocking):
            return self._operator.poll(prompt)
        return self._operator(prompt.step, prompt.state, prompt.proposal)

    def _due(self, context, state, step: int, now: float) -> float:
        """When the answer to the prompt of `step` is due: `indication_delay(step)` seconds after
        the prompt was first seen, for an operator that has one (`hrc_drake.tasks.interaction.
        DelayedIndications`, the interface's delay), else at once (a person in the browser)."""
        asked, due = context.get_abstract_state(self._asked).get_value()
        if asked != step:
            operator = self._operator
            delay = (
                operator.indication_delay(step) if isinstance(operator, DelaysIndications) else 0
            )
            due = now + float(delay)
            state.get_mutable_abstract_state(self._asked).set_value((step, due))
        return due

    def _seat_bolts(self, context, bolts: frozenset, pending: frozenset):
        """The bolts of the pending parts that now rest in a seat, let go, take there."""
        if not pending:
            return bolts, pending
        configuration = self._configuration.Eval(context)
        resting = self._resting.Eval(context) if self._resting.HasValue(context) else pending
        for part in pending & resting:
            weld = bolt_weld(configuration, part)
            # A part on a host is bolted to it once the host is bolted (it always is first:
            # the robot places a host before anything on it).
            takes = weld is not None and (
                "/" not in weld.seat or weld.support in {b.part for b in bolts}
            )
            if takes:
                bolts, pending = bolts | {weld}, pending - {part}
        return bolts, pending

    def _parts_at(self, context, token: str) -> frozenset[str]:
        """The parts that sit at `token`."""
        layout = self._configuration.Eval(context).layout()
        return frozenset(part for part, at in layout.items() if at == token)


__all__ = ["ActivityKind", "OperatorActivity", "SimulatedOperator", "bolt_weld"]
