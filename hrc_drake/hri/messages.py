"""The messages between the robot and the operator's interface (the paper's HRI: a touch menu,
a pointer, gestures).

The controller shows a `Prompt` on the interface; the operator answers with an `Indication`. Both
are small immutable values, the same whether the interface is a script, a population model, a
person in the browser or, one day, a real touch panel: they are all the controller ever learns
of the operator's intent. (The operator's body is measured separately, by the body tracker.)

A task boundary, in messages:
1. The controller prompts `CHOOSE` at `step` k with its proposal; the operator indicates a task
   (`Indication(step=k, task=...)`).
2. The robot picks, carries and places the part and prompts `BOLT` at step k while it holds the
   part still; the operator bolts it and indicates `bolted` for step k; the robot releases.
   (For an undo the operator takes the bolts out before the robot takes the part back.)
3. When the robot cannot do the task (a part it dropped and cannot pick again, a path that
   stays blocked), it prompts `HANDOVER` at step k: the operator does the task by hand (places
   and bolts the part) and indicates `done` for step k; the robot reads the cell and goes on.

A prompt left unanswered is asked again (`asked` counts how often), so that an interface that
lost the question, or a click, shows it afresh.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class PromptKind(StrEnum):
    """What the controller asks of the operator."""

    NONE = "none"  # nothing asked
    CHOOSE = "choose"  # a task boundary: confirm the proposal or indicate another task
    BOLT = "bolt"  # the robot holds the part in place: bolt it, then say so
    HANDOVER = "handover"  # the robot cannot do the task: do it by hand, then say so


@dataclass(frozen=True)
class Prompt:
    """What the interface shows: the step (decision steps count from 1), the kind of question,
    the MDP state (the sequence of tasks so far), the robot's proposal, the part moved (the
    part instance, once known) and, at a `CHOOSE`, the task the robot has already started on
    while it waits for the answer ("": it waits, still). `asked` counts how often the same
    question was asked again for want of an answer (0: the first time); `reason` says why a
    `HANDOVER` is handed over."""

    step: int = 0
    kind: PromptKind = PromptKind.NONE
    state: tuple[str, ...] = ()
    proposal: str = ""
    part: str = ""
    committed: str = ""
    asked: int = 0
    reason: str = ""

    def __deepcopy__(self, memo) -> Prompt:
        return self  # immutable (Drake copies abstract values often)


@dataclass(frozen=True)
class Indication:
    """The operator's latest word: the task indicated at `step` (None: not yet), whether the
    part of `step` is bolted, and whether the operator has done the task of `step` by hand (a
    `HANDOVER`). `time` is when it was given (seconds, the station's clock)."""

    step: int = 0
    task: str | None = None
    bolted: bool = False
    time: float = 0.0
    done: bool = False

    def __deepcopy__(self, memo) -> Indication:
        return self

    def answers(self, prompt: Prompt) -> bool:
        """Whether this indication answers `prompt` (the same step, and what it asks)."""
        if prompt.kind == PromptKind.CHOOSE:
            return self.step == prompt.step and self.task is not None
        if prompt.kind == PromptKind.BOLT:
            return self.step == prompt.step and self.bolted
        if prompt.kind == PromptKind.HANDOVER:
            return self.step == prompt.step and self.done
        return False


__all__ = ["Indication", "Prompt", "PromptKind"]
