"""The decision loop at task boundaries: the robot proposes, the operator performs.

`run_decisions` plays an assembly from the empty base: at each decision step the policy
proposes a task, the operator performs it or another feasible one, and the loop goes on until a
terminal state. It is what `hrc-drake react` prints and what the cell's supervisor does with
physics in between.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.solve import tasks_to_finish

# (decision step from 1, state, robot's proposal) -> the task the operator performs
Operator = Callable[[int, tuple[str, ...], str], str]


class DecisionError(RuntimeError):
    """The loop cannot go on: an infeasible task, or no terminal state within the step limit."""


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
            raise DecisionError(
                f"step {step}: task {performed!r} is not feasible in state {list(state)}; "
                f"feasible tasks are {sorted(feasible)}"
            )
        index = feasible[performed]
        state = space.sequence(index)
        states.append(state)
        decisions.append(Decision(step, states[-2], proposal, performed))
    if space.kind[index] == StateKind.TERMINAL:
        return states, decisions
    raise DecisionError(
        f"no terminal state after {max_steps} decision steps (at {list(state)}); the policy "
        "loops — retrain it (hrc-drake train --schedule full) or use the exact one"
    )


def minimum_effort_violations(space: StateSpace, policy: Policy) -> dict[tuple[str, ...], str]:
    """States from which following the policy does not finish in the fewest tasks.

    Maps each such state to a short explanation; empty when the policy is minimum-effort from
    every non-terminal state.
    """
    best = tasks_to_finish(space)
    bad = {}
    for s in np.flatnonzero(space.kind != StateKind.TERMINAL):
        seq = space.sequence(int(s))
        if best[s] < 0:
            continue
        try:
            states, _ = run_decisions(space, policy, start=seq, max_steps=int(best[s]) + 1)
        except DecisionError:
            bad[seq] = f"does not finish within {best[s]} tasks"
            continue
        if len(states) - 1 != best[s]:
            bad[seq] = f"takes {len(states) - 1} tasks, fewest is {best[s]}"
    return bad
