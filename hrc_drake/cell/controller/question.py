"""The operator's interface as the Supervisor keeps it: the one writer of its `Question` record
(the prompt up, when the operator was asked and answered).

The parts of the Supervisor change the question only through these functions, each one thing
that happens at the interface. Values only; no Drake.
"""

from __future__ import annotations

from dataclasses import replace

from hrc_drake.cell.controller.supervisor_state import Question, SupervisorStatus
from hrc_drake.hri.messages import Prompt, PromptKind


def asked(s: SupervisorStatus, prompt: Prompt, now: float) -> SupervisorStatus:
    """`s` with a new question, `prompt`, first asked at `now` (a task boundary)."""
    return replace(s, question=Question(prompt=prompt, asked_at=now, prompted_at=now))


def answered(s: SupervisorStatus, now: float) -> SupervisorStatus:
    """`s` with the operator's indication come at `now`."""
    return replace(s, question=replace(s.question, indicated_at=now))


def asked_again(s: SupervisorStatus, now: float) -> SupervisorStatus:
    """`s` with the same prompt asked again at `now` (its `asked` count one up, so that an
    interface shows it afresh)."""
    prompt = replace(s.question.prompt, asked=s.question.prompt.asked + 1)
    return replace(s, question=replace(s.question, asked_at=now, prompt=prompt))


def handed_over(s: SupervisorStatus, prompt: Prompt, now: float) -> SupervisorStatus:
    """`s` asking the operator, from `now`, to do the task by hand (`prompt`: `HANDOVER`)."""
    question = replace(s.question, prompt=prompt, asked_at=now, prompted_at=now)
    return replace(s, question=question)


def holding(s: SupervisorStatus, prompt: Prompt, now: float) -> SupervisorStatus:
    """`s` prompting the bolts (`prompt`: `BOLT`), the part held in place since `now`."""
    return replace(s, question=replace(s.question, prompt=prompt, held_at=now))


def cleared(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with no prompt up (the task is done, or done by hand)."""
    prompt = replace(s.question.prompt, kind=PromptKind.NONE)
    return replace(s, question=replace(s.question, prompt=prompt))


def withdrawn(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with a `BOLT` prompt withdrawn (nobody should reach in to bolt now); a question
    still open (anticipating, the indication not in yet) stays up: withdrawn, it could never
    be answered and the robot would wait for it forever."""
    return s if s.question.prompt.kind == PromptKind.CHOOSE else cleared(s)


def uncommitted(s: SupervisorStatus) -> SupervisorStatus:
    """`s` with the prompt no longer saying the robot is on its way to a task."""
    prompt = replace(s.question.prompt, committed="")
    return replace(s, question=replace(s.question, prompt=prompt))


__all__ = [
    "answered",
    "asked",
    "asked_again",
    "cleared",
    "handed_over",
    "holding",
    "uncommitted",
    "withdrawn",
]
