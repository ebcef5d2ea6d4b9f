"""Operator populations: seeded operator models, selectable by name, for Monte Carlo evaluation.

Each model is a callable ``(step, state, proposal) -> task performed`` (the protocol of
`hrc_drake.tasks.decide.Operator`) and offers ``bolt_scale(step)``, the factor on the operator's
part of a task's time (1 but for `slow`). One instance plays one run: models with memory
(`habitual`, `change-of-mind`) remember that run only. Built-in models:

- ``follows``: always performs the proposal.
- ``random``: any feasible task, uniformly.
- ``habitual`` (``order``: a task token, default the host part on the highest slots, ``S23`` in
  the flange case): performs its habit whenever it is feasible and not yet done in this run,
  else follows.
- ``mistake-prone`` (``p``): a proposed placement the spec lists under ``mistakes`` lands, with
  probability p, in a confusable seat (as `StochasticOperator.alternatives` lists them).
- ``change-of-mind`` (``p``): with probability p, undoes the part just placed instead of the
  proposal, at most once per state.
- ``slow`` (``growth``): follows; its bolting time grows along the run, ``bolt_scale(step) =
  1 + growth * (step - 1)``.

`register_operator_model` adds a user's model: any ``factory(space, seed=0, **params)``
returning such a callable (a class works).
"""

from __future__ import annotations

import inspect
import random
from collections.abc import Callable
from typing import Any

from hrc_drake.hri.operator import StochasticOperator
from hrc_drake.paths import UsageError
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

OperatorFactory = Callable[..., Any]


def _probability(name: str, value: Any) -> float:
    try:
        p = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"operator model parameter {name}={value!r}: not a number") from None
    if not 0.0 <= p <= 1.0:
        raise UsageError(f"operator model parameter {name}={p}: must be within [0, 1]")
    return p


class OperatorModel:
    """Base of the built-in models: the space, a seeded random generator, a bolting scale of 1."""

    def __init__(self, space: StateSpace, seed: int = 0):
        self.space = space
        self.rng = random.Random(seed)

    def feasible(self, state: tuple[str, ...]) -> list[str]:
        """Tasks feasible in `state` (placements, then undo)."""
        return [t for t, _ in self.space.tasks(self.space.index(state))]

    def bolt_scale(self, step: int) -> float:
        """Factor on the operator's part of the time of the task at decision `step`."""
        return 1.0

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        return proposal


class Follows(OperatorModel):
    """Always performs the robot's proposal."""


class RandomOperator(OperatorModel):
    """Performs any feasible task, uniformly at random."""

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        return self.rng.choice(self.feasible(state))


def default_habit(space: StateSpace) -> str:
    """The host part's placement on the highest slots (``S23`` in the flange case); else the last
    placement token."""
    spec, table = space.spec, space.table
    hosts = {p.symbol for p in spec.parts if p.is_host}
    tokens = [
        t
        for i, t in enumerate(table.tokens)
        if spec.parts[table.part[i]].symbol in hosts and spec.mounts[table.mount[i]].on == "base"
    ]
    if not tokens:
        return table.tokens[-1]
    return max(tokens, key=lambda t: (max(table.slots[table.tokens.index(t)]), t))


class Habitual(OperatorModel):
    """Performs its habit (`order`, a task) whenever feasible and not yet done; else follows."""

    def __init__(self, space: StateSpace, seed: int = 0, order: str | None = None):
        super().__init__(space, seed)
        order = default_habit(space) if order in (None, "") else str(order)
        if order not in space.tokens:
            raise UsageError(
                f"operator model habitual: order={order!r} is not a task of assembly "
                f"{space.spec.name!r}; use one of {', '.join(space.tokens)}"
            )
        self.order = order
        self.done = False

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        if not self.done and self.order in self.feasible(state):
            self.done = True
            return self.order
        return proposal


class MistakeProne(OperatorModel):
    """Confirms; a confusable placement lands in another seat of its kind with probability p."""

    def __init__(self, space: StateSpace, seed: int = 0, p: float = 0.2):
        super().__init__(space, seed)
        self.p = _probability("p", p)
        self._seats = StochasticOperator(space, 0.0, self.p, seed)

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        confusable = self._seats.alternatives(state, proposal)
        if confusable and self.rng.random() < self.p:
            return self.rng.choice(confusable)
        return proposal


class ChangeOfMind(OperatorModel):
    """With probability p undoes the part just placed (at most once per state); else follows."""

    def __init__(self, space: StateSpace, seed: int = 0, p: float = 0.2):
        super().__init__(space, seed)
        self.p = _probability("p", p)
        self.changed: set[tuple[str, ...]] = set()

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        if state and proposal != UNDO and state not in self.changed:
            self.changed.add(state)
            if self.rng.random() < self.p:
                return UNDO
        return proposal


class Slow(OperatorModel):
    """Follows; bolting takes ``1 + growth * (step - 1)`` times as long at decision `step`."""

    def __init__(self, space: StateSpace, seed: int = 0, growth: float = 0.1):
        super().__init__(space, seed)
        try:
            self.growth = float(growth)
        except (TypeError, ValueError):
            raise UsageError(f"operator model slow: growth={growth!r} is not a number") from None
        if self.growth < 0:
            raise UsageError(f"operator model slow: growth={self.growth} must be >= 0")

    def bolt_scale(self, step: int) -> float:
        """``1 + growth * (step - 1)``."""
        return 1.0 + self.growth * (step - 1)


OPERATOR_MODELS: dict[str, OperatorFactory] = {
    "follows": Follows,
    "random": RandomOperator,
    "habitual": Habitual,
    "mistake-prone": MistakeProne,
    "change-of-mind": ChangeOfMind,
    "slow": Slow,
}


def register_operator_model(name: str, factory: OperatorFactory) -> None:
    """Add (or replace) a model: `factory(space, seed=0, **params)` returns the operator."""
    if not name or not callable(factory):
        raise ValueError("register_operator_model needs a name and a callable factory")
    OPERATOR_MODELS[name] = factory


def model_parameters(name: str) -> list[str]:
    """Names of the parameters of model `name` (beyond space and seed)."""
    factory = OPERATOR_MODELS[name]
    sig = inspect.signature(factory)
    return [p for p in sig.parameters if p not in ("self", "space", "seed")]


def make_operator_model(name: str, space: StateSpace, seed: int = 0, **params: Any):
    """The operator model `name` for `space`, seeded; UsageError (a ValueError) naming the known
    models or the known parameters when the name or a parameter is unknown."""
    if name not in OPERATOR_MODELS:
        raise UsageError(
            f"unknown operator model {name!r}; known models: {', '.join(sorted(OPERATOR_MODELS))}"
        )
    factory = OPERATOR_MODELS[name]
    sig = inspect.signature(factory)
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values())
    known = model_parameters(name)
    for key in params:
        if not takes_any and key not in known:
            raise UsageError(
                f"operator model {name!r} has no parameter {key!r}; its parameters: "
                f"{', '.join(known) or 'none'}"
            )
    return factory(space, seed=seed, **params)
