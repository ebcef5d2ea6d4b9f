"""What a policy, a decider or an operator may offer beyond what every one has, declared (no
Drake). Every policy answers `next_task(state)` and every operator is called with a prompt
(`hrc_drake.tasks.decide.Operator`); the layers that use more ask with `isinstance` against
these runtime-checkable protocols, so that what a part offers is written down once, here.

Policies and deciders:
- `Commits`: the placement it bets on while the operator indicates (anticipation), which may
  differ from its proposal; without it the robot bets on its proposal when that is a placement.
- `PredictsTasks`: the tasks the operator may perform next, most likely first (plans asked
  ahead); without it, the policy's own next task.
- `ObservesTasks`: hears every task as the cell observed it (a learning decider).
- `HasOperatorModel`: carries an operator model (`mpc`) whose answer probabilities rank what
  to plan ahead.

Operators:
- `AskedWithoutBlocking`: answers a prompt when it can (`poll`, None meanwhile): a person in
  the browser.
- `DelaysIndications`: gives its indication `indication_delay(step)` seconds after the prompt
  (the interface's delay).
- `TiresAlongTheRun`: bolts `bolt_scale(step)` times the nominal bolting time.
- `TotalDelay`: the sum of the delays it drew (reported by cell evaluations).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Commits(Protocol):
    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The placement bet on at `state` when `proposal` is proposed (None: no bet)."""


@runtime_checkable
class PredictsTasks(Protocol):
    def predicted_tasks(self, state: tuple[str, ...]) -> Sequence[str]:
        """The tasks the operator may perform at `state`, most likely first."""


@runtime_checkable
class ObservesTasks(Protocol):
    def observe(self, record: Any) -> None:
        """Hear a task as the cell observed it."""


@runtime_checkable
class HasOperatorModel(Protocol):
    model: Any  # an operator model with `outcome_probabilities(state, proposal)`, or None


@runtime_checkable
class AskedWithoutBlocking(Protocol):
    def poll(self, prompt: Any) -> str | None:
        """The task answered to `prompt`, or None while there is no answer."""


@runtime_checkable
class DelaysIndications(Protocol):
    def indication_delay(self, step: int) -> float:
        """Seconds from the prompt of decision `step` to the indication."""


@runtime_checkable
class TiresAlongTheRun(Protocol):
    def bolt_scale(self, step: int) -> float:
        """The factor on the nominal bolting time at decision `step`."""


@runtime_checkable
class TotalDelay(Protocol):
    def total_delay(self) -> float:
        """The sum of the indication delays drawn so far [s]."""


__all__ = [
    "AskedWithoutBlocking",
    "Commits",
    "DelaysIndications",
    "HasOperatorModel",
    "ObservesTasks",
    "PredictsTasks",
    "TiresAlongTheRun",
    "TotalDelay",
]
