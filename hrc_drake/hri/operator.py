"""Operators at the human-robot interface: who performs the task the robot proposes.

Each operator is a callable ``(step, state, proposal) -> task performed``, the protocol of
`hrc_drake.tasks.decide.Operator`: it confirms the proposal or performs another feasible task.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import dataclass, field

from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO


class OperatorScriptError(ValueError):
    """An operator script that cannot be read."""


def parse_operator_script(text: str) -> dict[int, str]:
    """Parse ``"1:F3,2:S12"`` (decision step: task performed instead of the proposal)."""
    script: dict[int, str] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        step_text, sep, task = item.partition(":")
        if not sep or not step_text.strip().isdigit() or not task.strip():
            raise OperatorScriptError(
                f'operator script {text!r}: {item!r} is not STEP:TASK (e.g. "1:F3,2:S12")'
            )
        step = int(step_text)
        if step < 1:
            raise OperatorScriptError(f"operator script {text!r}: steps count from 1, got {step}")
        if step in script:
            raise OperatorScriptError(f"operator script {text!r}: step {step} given twice")
        script[step] = task.strip()
    return script


@dataclass(frozen=True)
class ScriptedOperator:
    """Performs the scripted task at the scripted decision steps; follows the robot otherwise."""

    script: Mapping[int, str] = field(default_factory=dict)

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        return self.script.get(step, proposal)


class StochasticOperator:
    """Overrides the proposal with another feasible task, or misplaces a part, at random.

    With `override_prob` the operator performs another feasible task (uniformly); otherwise,
    with `mistake_prob`, a proposed placement the spec lists under ``mistakes`` lands in
    another free seat of the same kind. Seeded: the same seed gives the same run.
    """

    def __init__(self, space: StateSpace, override_prob: float, mistake_prob: float, seed: int = 0):
        for name, p in (("override_prob", override_prob), ("mistake_prob", mistake_prob)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} must be within [0, 1], got {p}")
        self.space = space
        self.override_prob = override_prob
        self.mistake_prob = mistake_prob
        self.rng = random.Random(seed)

    def alternatives(self, state: tuple[str, ...], proposal: str) -> list[str]:
        """Seats the operator may confuse with the proposed placement."""
        if proposal == UNDO:
            return []
        spec, table = self.space.spec, self.space.table
        index = table.tokens.index(proposal)
        mount = spec.mounts[table.mount[index]]
        if (mount.part, mount.on) not in spec.mistakes:
            return []
        tasks = [t for t, _ in self.space.tasks(self.space.index(state)) if t != UNDO]
        return [
            t
            for t in tasks
            if t != proposal and table.mount[table.tokens.index(t)] == table.mount[index]
        ]

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        tasks = [t for t, _ in self.space.tasks(self.space.index(state))]
        others = [t for t in tasks if t != proposal]
        if others and self.rng.random() < self.override_prob:
            return self.rng.choice(others)
        confusable = self.alternatives(state, proposal)
        if confusable and self.rng.random() < self.mistake_prob:
            return self.rng.choice(confusable)
        return proposal
