"""The decision loop at task boundaries: the robot proposes, the operator performs.

`run_decisions` plays an assembly from the empty base: at each decision step the policy
proposes a task, the operator performs it or another feasible one, and the loop goes on until a
terminal state. It is what `hrc-drake react` prints and what the cell's supervisor does with
physics in between.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.policy_check import check_policy
from hrc_drake.tasks.tokens import UNDO

# (decision step from 1, state, robot's proposal) -> the task the operator performs
Operator = Callable[[int, tuple[str, ...], str], str]


class DecisionError(RuntimeError):
    """The loop cannot go on: an infeasible task, or no terminal state within the step limit."""


class InfeasibleTaskError(DecisionError):
    """The operator performed a task that is not feasible in the state it was performed in."""

    def __init__(self, step: int, task: str, state: tuple[str, ...], feasible: list[str]):
        self.step, self.task, self.state, self.feasible = step, task, state, feasible
        super().__init__(
            f"step {step}: task {task!r} is not feasible in state {list(state)}; "
            f"feasible tasks are {feasible}"
        )


class ScriptPastEndError(DecisionError):
    """An operator script names decision steps after the run has reached a terminal state."""

    def __init__(self, late: Mapping[int, str], steps: int):
        self.late, self.steps = dict(late), steps
        listed = ", ".join(f"{k}:{t}" for k, t in sorted(late.items()))
        super().__init__(
            f"operator script: step(s) {listed} come after the end of the run, which reached a "
            f"terminal state after {steps} decision step(s); script steps 1..{steps} only"
        )


class StepLimitError(DecisionError):
    """No terminal state within the step limit."""


def follow(_step: int, _state: tuple[str, ...], proposal: str) -> str:
    """An operator who always confirms the robot's proposal."""
    return proposal


@dataclass(frozen=True)
class Decision:
    """One decision step: where it started, what the robot proposed, what was done."""

    step: int
    state: tuple[str, ...]
    proposed: str
    performed: str


def run_decisions(
    space: StateSpace,
    policy: Policy,
    operator: Operator = follow,
    max_steps: int = 50,
    start: tuple[str, ...] = (),
) -> tuple[list[tuple[str, ...]], list[Decision]]:
    """Play from `start` to a terminal state; returns the states visited and the decisions."""
    state = tuple(start)
    index = space.index(state)
    states, decisions = [state], []
    for step in range(1, max_steps + 1):
        if space.kind[index] == StateKind.TERMINAL:
            return states, decisions
        proposal = policy.next_task(state)
        performed = operator(step, state, proposal)
        feasible = dict(space.tasks(index))
        if performed not in feasible:
            raise InfeasibleTaskError(step, performed, state, sorted(feasible))
        index = feasible[performed]
        state = space.sequence(index)
        states.append(state)
        decisions.append(Decision(step, states[-2], proposal, performed))
    if space.kind[index] == StateKind.TERMINAL:
        return states, decisions
    raise StepLimitError(_step_limit_reason(space, policy, states, decisions, max_steps))


def _step_limit_reason(
    space: StateSpace,
    policy: Policy,
    states: list[tuple[str, ...]],
    decisions: list[Decision],
    max_steps: int,
) -> str:
    """Why the loop hit its step limit: the operator's deviations, or a policy that loops.

    The policy is a function of the state, so after the operator's last deviation it either
    repeats a state (it loops) or reaches a terminal state in a number of steps we can count.
    """
    head = f"no terminal state after {max_steps} decision steps (at {list(states[-1])})"
    overridden = [d for d in decisions if d.performed != d.proposed]
    last = overridden[-1].step if overridden else 0
    state, seen, more = states[last], set(), 0
    while space.kind[space.index(state)] != StateKind.TERMINAL:
        if state in seen:
            where = f" from {list(states[last])}" if last else ""
            return (
                f"{head}: the policy loops{where} — retrain it (hrc-drake train --schedule "
                "full) or use the exact one"
            )
        seen.add(state)
        task = policy.next_task(state)
        feasible = dict(space.tasks(space.index(state)))
        if task not in feasible:
            return (
                f"{head}: the policy proposes {task!r} in {list(state)}, where it is not feasible"
            )
        state = space.sequence(feasible[task])
        more += 1
    if not overridden:
        return (
            f"{head}: the policy needs {more} task(s) from {list(states[0])}; raise max_steps "
            f"(--max-steps) to at least {more}"
        )
    undos = [d.step for d in overridden if d.performed == UNDO]
    forced = f" (undo at {undos})" if undos else ""
    steps = [d.step for d in overridden]
    return (
        f"{head}: the operator overrode the robot at step(s) {steps}{forced}; after step "
        f"{last} the policy needs {more} more task(s), {max_steps - last} step(s) were left; "
        f"raise max_steps (--max-steps) to at least {last + more} or shorten the operator's "
        "script"
    )


def check_script_within_run(script: Mapping[int, str], decisions: list[Decision]) -> None:
    """ScriptPastEndError if `script` (step -> task) names steps the run never reached.

    Call it after a run that reached a terminal state: a scripted step after the end would
    otherwise be silently ignored.
    """
    late = {k: t for k, t in script.items() if k > len(decisions)}
    if late:
        raise ScriptPastEndError(late, len(decisions))


def minimum_effort_violations(space: StateSpace, policy: Policy) -> dict[tuple[str, ...], str]:
    """States from which following the policy does not finish in the fewest tasks.

    Maps each such state to a short explanation; empty when the policy is minimum-effort from
    every non-terminal state. Judged by the number of tasks (`tasks_to_finish`: an equally
    short route counts), on every state at once (`hrc_drake.tasks.policy_check.check_policy`).
    """
    check = check_policy(space, policy, values=False)
    bad = {}
    for s in np.flatnonzero(check.not_minimum).tolist():
        steps, fewest = int(check.walks.steps[s]), int(check.fewest[s])
        if steps >= 0:
            why = f"takes {steps} tasks, fewest is {fewest}"
        elif check.walks.loops[s]:
            why = f"never finishes (the policy loops; fewest is {fewest})"
        else:
            why = f"never finishes (the policy gives no task on the way; fewest is {fewest})"
        bad[space.sequence(s)] = why
    return bad
