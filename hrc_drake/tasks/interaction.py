"""How the operator's indication reaches the robot, and what a robot that moves on its prediction
gains or pays: the interaction timeline of one task boundary (no Drake).

At a task boundary the robot proposes a task; the operator indicates the task to do through the
human-robot interface (the paper's section 5: a marker *pointer* tracked by motion capture,
*gesture*s read by a Leap Motion, a *touch* menu). The indication arrives after a delay drawn
per interface (`IndicationDelay`). Two interaction modes:

- ``wait`` (the cell until now): the robot waits for the indication, then does the task. A
  boundary costs the delay.
- ``anticipate`` (the default; the paper: "the target position of the flange is indicated by
  the human through HRI during the execution of the job"): the decider commits to a placement
  (a part and a predicted seat) and the robot starts at once, or it waits when its prediction is
  too uncertain. When the indication comes, the robot is somewhere along the committed task:

  * the indicated task is the committed one (*right*): the delay was spent moving; the robot
    only waits if it reached the seat's pre-place pose before the indication;
  * the same part to another seat (*re-target*): nothing is lost while the part is still picked
    (the pick is the same); during the carry the detour grows with the way covered toward the
    wrong seat, up to the cost table's planned re-target (carry to the predicted seat's
    pre-place, then on to the indicated one);
  * another part, or undo (*swap*): the loss grows with the way covered toward the wrong part,
    up to the table's planned swap once the part is lifted (put it back in its tray home,
    release, then go for the indicated one); during the carry the robot must also come back
    the way it went.

  A task the operator indicates that the robot cannot plan (the operator's by the cost table)
  is a swap whatever the part: the robot puts its part back, then hands the task over.

  `extra_seconds` is this model: piecewise linear in the delay between the committed task's
  milestones of the cost table (`EdgeCost.carry_start`, `EdgeCost.carry_end`), a first-order
  model of the cell's re-target and swap that the cell's own timings are to be compared with.

`InteractionCosts` turns the model into what a decider weighs: the expected seconds a boundary
adds for each bet (commit to the proposal, or wait), over the delay distribution, given the
probabilities of the operator's answers; `best_bet` picks the cheaper. The same seed draws the
same delays (`IndicationDelay.sample` takes the caller's generator).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from statistics import NormalDist

import numpy as np

from hrc_drake.tasks.bets import Bet, bet_kind
from hrc_drake.tasks.costs import CostTable, CostTableError
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

ANTICIPATE, WAIT = "anticipate", "wait"
MODES = (ANTICIPATE, WAIT)
INTERFACES = ("pointer", "gesture", "touch")
DISTRIBUTIONS = ("lognormal", "fixed")
DEFAULT_MODE, DEFAULT_INTERFACE = ANTICIPATE, "pointer"
# Expectations over the delay use its quantiles at the midpoints of this many equal-probability
# bins: deterministic, and within 0.2 % of the exact mean for the defaults below.
DELAY_NODES = 64
DELAY_STREAM = 7_117  # the delays' own random stream beside the operator's (any fixed number)


class InteractionError(ValueError):
    """A mode, interface or delay that cannot be used; the message names it and the fix."""


@dataclass(frozen=True)
class IndicationDelay:
    """Seconds from the robot's proposal to the operator's indication: `fixed` at `median`, or
    `lognormal` with that median and `sigma` (the standard deviation of the log: 0.3 puts the
    middle 90 % within a factor 1.6 of the median). Human response times are right-skewed and
    commonly modelled as log-normal (R. D. Luce, *Response Times*, Oxford 1986, ch. 1)."""

    distribution: str = "lognormal"
    median: float = 2.0
    sigma: float = 0.3

    def check(self, where: str = "delay") -> IndicationDelay:
        """InteractionError naming the key unless the distribution and its parameters are valid."""
        if self.distribution not in DISTRIBUTIONS:
            raise InteractionError(
                f"{where}.distribution: unknown distribution {self.distribution!r}; use one of "
                f"{', '.join(DISTRIBUTIONS)}"
            )
        for key in ("median", "sigma"):
            value = getattr(self, key)
            if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
                raise InteractionError(
                    f"{where}.{key}: a delay parameter is a number of seconds >= 0, got {value!r}"
                )
        if self.distribution == "lognormal" and self.median <= 0:
            raise InteractionError(
                f"{where}.median: a lognormal delay needs a median > 0 s, got {self.median}; "
                "for no delay use distribution: fixed, median: 0"
            )
        return self

    def sample(self, rng: np.random.Generator) -> float:
        """One delay [s], drawn with `rng` (a fixed delay draws nothing)."""
        if self.distribution == "fixed" or self.sigma == 0:
            return float(self.median)
        return float(self.median * math.exp(self.sigma * rng.standard_normal()))

    @property
    def mean(self) -> float:
        """The expected delay [s]."""
        if self.distribution == "fixed":
            return float(self.median)
        return float(self.median * math.exp(0.5 * self.sigma**2))

    def nodes(self, n: int = DELAY_NODES) -> np.ndarray:
        """`n` equally likely delays (quantiles at bin midpoints), for expectations."""
        if self.distribution == "fixed" or self.sigma == 0:
            return np.full(1, float(self.median))
        z = np.array([NormalDist().inv_cdf((i + 0.5) / n) for i in range(n)])
        return self.median * np.exp(self.sigma * z)

    def to_json(self) -> dict[str, float | str]:
        """The parameters and the mean, for reports."""
        return {
            "distribution": self.distribution,
            "median": self.median,
            "sigma": self.sigma if self.distribution == "lognormal" else 0.0,
            "mean": round(self.mean, 4),
        }


# The paper names the interfaces (section 5) but gives no times: these figures are our
# assumption, to be replaced by measurements. Each is the time from the proposal appearing to the
# indication registered: pointer, take the marker pointer and hold it on the target hole until the
# motion capture registers it; gesture, raise the hand over the Leap Motion and hold the gesture
# until it is recognised (the fastest: nothing to reach for); touch, turn to the display, find the
# task in the menu and tap it.
DEFAULT_DELAYS: Mapping[str, IndicationDelay] = {
    "pointer": IndicationDelay("lognormal", 2.0, 0.3),
    "gesture": IndicationDelay("lognormal", 1.5, 0.35),
    "touch": IndicationDelay("lognormal", 2.5, 0.3),
}


@dataclass(frozen=True)
class Interaction:
    """An interaction mode, the interface and its indication delay (default: the interface's)."""

    mode: str = DEFAULT_MODE
    interface: str = DEFAULT_INTERFACE
    delay: IndicationDelay = field(default_factory=lambda: DEFAULT_DELAYS[DEFAULT_INTERFACE])

    @property
    def anticipates(self) -> bool:
        """Whether the robot may start on its prediction."""
        return self.mode == ANTICIPATE

    def to_json(self) -> dict:
        """Mode, interface and delay, for reports."""
        return {"mode": self.mode, "interface": self.interface, "delay": self.delay.to_json()}


def make_interaction(
    mode: str | None = None, interface: str | None = None, delay: IndicationDelay | None = None
) -> Interaction:
    """The interaction `mode` over `interface` (defaults: anticipate, pointer) with `delay`
    (default: the interface's, `DEFAULT_DELAYS`); InteractionError naming a bad value."""
    mode = DEFAULT_MODE if mode is None else mode
    interface = DEFAULT_INTERFACE if interface is None else interface
    if mode not in MODES:
        raise InteractionError(f"unknown interaction mode {mode!r}; use one of {', '.join(MODES)}")
    if interface not in INTERFACES:
        raise InteractionError(
            f"unknown interface {interface!r}; use one of {', '.join(INTERFACES)}"
        )
    delay = DEFAULT_DELAYS[interface] if delay is None else delay.check()
    return Interaction(mode, interface, delay)


def extra_seconds(kind: Bet, delay, carry_start: float, carry_end: float, planned: float):
    """Seconds a bet adds to the indicated task's time when the indication comes after `delay`
    (a number or an array), the committed task's carry spanning [carry_start, carry_end] from
    its start, and `planned` the table's full re-target or swap (0 for a right bet). See the
    module docstring."""
    d = np.asarray(delay, dtype=float)
    late = np.maximum(0.0, d - carry_end)  # waited above the predicted seat
    span = max(carry_end - carry_start, 1e-9)
    along = np.clip(d - carry_start, 0.0, span)  # way covered along the carry
    if kind == Bet.RIGHT:
        out = late
    elif kind == Bet.RETARGET:
        out = planned * along / span + late
    else:
        before = np.minimum(d, carry_start) / max(carry_start, 1e-9)
        out = planned * before + 2.0 * along + late
    return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class Step:
    """One boundary's interaction: the task committed to (None: the robot waited), the delay
    drawn, the seconds it added, and whether the robot re-targeted or swapped."""

    committed: str | None
    delay: float
    seconds: float
    retargeted: bool = False
    swapped: bool = False


class InteractionCosts:
    """The interaction's seconds at task level, from a cost table: what a bet is expected to add
    (for deciders) and what it adds for a drawn delay (for runs).

    In ``wait`` mode every boundary costs its delay. In ``anticipate`` mode the table must give
    each placement's carry milestones and each (state, committed, indicated) bet's planned
    seconds (`hrc-drake costs` plans them); CostTableError naming the fix otherwise.
    """

    def __init__(self, space: StateSpace, table: CostTable, interaction: Interaction):
        self.space, self.table, self.interaction = space, table, interaction
        self.nodes = interaction.delay.nodes()
        self.wait_seconds = float(self.nodes.mean())
        self._expected: dict[tuple[tuple[str, ...], str, str], float] = {}
        self._by_figures: dict[tuple, float] = {}  # bets with the same figures: computed once
        if interaction.anticipates:
            problem = table.anticipation_problem()
            if problem:
                raise CostTableError(
                    f"interaction anticipate needs the cost table's re-target and swap times: "
                    f"{problem}; plan a table with `hrc-drake costs --out FILE`, or use "
                    "--interaction wait"
                )

    def _figures(self, state: tuple[str, ...], committed: str, indicated: str):
        kind = self.table.bet_kind(self.space, state, committed, indicated)
        edge = self.table.cost(state, committed)
        planned = 0.0 if kind == Bet.RIGHT else self.table.bet_seconds(state, committed, indicated)
        return kind, edge.carry_start, edge.carry_end, planned

    def expected(self, state: tuple[str, ...], committed: str, indicated: str) -> float:
        """Expected seconds added when the robot committed to `committed` and the operator
        indicates `indicated` (over the delay distribution)."""
        key = (state, committed, indicated)
        value = self._expected.get(key)
        if value is None:
            figures = self._figures(state, committed, indicated)
            value = self._by_figures.get(figures)
            if value is None:
                value = float(np.mean(extra_seconds(*figures[:1], self.nodes, *figures[1:])))
                self._by_figures[figures] = value
            self._expected[key] = value
        return value

    def bets(self, state: tuple[str, ...]) -> list[str]:
        """The placements the robot may commit to in `state` (none in `wait` mode, nor one the
        robot cannot plan: the operator's by the table)."""
        if not self.interaction.anticipates:
            return []
        tasks = self.space.tasks(self.space.index(state))
        return [t for t, _ in tasks if t != UNDO and not self.table.by_operator(state, t)]

    def commit_seconds(
        self, state: tuple[str, ...], committed: str, probabilities: Mapping[str, float]
    ) -> float:
        """Expected seconds added by committing to `committed` when the operator answers with
        `probabilities` (task -> probability)."""
        return sum(
            p * self.expected(state, committed, t) for t, p in probabilities.items() if p > 0
        )

    def best_bet(
        self, state: tuple[str, ...], probabilities: Mapping[str, float], proposal: str
    ) -> tuple[str | None, float]:
        """Commit to the proposal, or wait: whichever adds fewer expected seconds when the
        operator answers with `probabilities` (task -> probability); and those seconds. The
        robot bets on what it proposes (moving toward another task than the one the interface
        shows would contradict it); it waits for an undo, and in ``wait`` mode. Ties commit."""
        state = tuple(state)
        if proposal not in self.bets(state):
            return None, self.wait_seconds
        seconds = self.commit_seconds(state, proposal, probabilities)
        if seconds <= self.wait_seconds + 1e-9:
            return proposal, seconds
        return None, self.wait_seconds

    def play(self, state: tuple[str, ...], committed: str | None, indicated: str, delay: float):
        """The `Step` of a boundary: the robot committed to `committed` (None: waited), the
        operator indicated `indicated` after `delay` seconds. A commitment to a task the robot
        cannot plan (the operator's by the table) never starts: the robot waits, as the cell's
        Supervisor does when it finds no plan for what it committed to."""
        if committed is None or self.table.by_operator(state, committed):
            return Step(None, delay, float(delay))
        kind, start, end, planned = self._figures(tuple(state), committed, indicated)
        seconds = float(extra_seconds(kind, delay, start, end, planned))
        return Step(committed, delay, seconds, kind == Bet.RETARGET, kind == Bet.SWAP)


class DelayedIndications:
    """An operator (any `hrc_drake.tasks.decide.Operator`) whose indication at each decision
    step comes after a delay drawn from `delay`, seeded (or drawn from `rng`, e.g. an
    evaluation run's `delay_generator`): `indication_delay(step)` is what the simulated station
    waits before it publishes the answer. Answers, and anything else the operator offers
    (`bolt_scale`, ...), are the wrapped operator's."""

    def __init__(
        self,
        operator,
        delay: IndicationDelay,
        seed: int = 0,
        rng: np.random.Generator | None = None,
    ):
        self.operator = operator
        self.delay = delay
        self._rng = rng if rng is not None else operator_delays(seed)
        self._drawn: dict[int, float] = {}

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        return self.operator(step, state, proposal)

    def indication_delay(self, step: int) -> float:
        """Seconds from the prompt of decision `step` to the indication (drawn once per step,
        in the order asked: steps come in order, so the same seed gives the same delays)."""
        if step not in self._drawn:
            self._drawn[step] = self.delay.sample(self._rng)
        return self._drawn[step]

    def total_delay(self) -> float:
        """The seconds of every delay drawn so far (one per decision step answered)."""
        return float(sum(self._drawn.values()))

    def __getattr__(self, name: str):
        if name == "operator":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.operator, name)


def bet_summary(space: StateSpace, table: CostTable, interaction: Interaction) -> dict:
    """The interaction's figures of a cost table, JSON-ready: the mode, interface and delay,
    the expected seconds of waiting for the indication, and per bet its kind, its planned
    seconds (at most) and the seconds it adds on average with this delay (None without bets)."""
    out = {**interaction.to_json(), "wait_seconds": round(float(interaction.delay.mean), 4)}
    if table.anticipation_problem() is not None:
        return {**out, "bets": None}
    priced = InteractionCosts(space, table, replace(interaction, mode=ANTICIPATE))
    rows = []
    for (state, committed, indicated), planned in sorted(
        (table.bets or {}).items(), key=lambda kv: (len(kv[0][0]), kv[0])
    ):
        rows.append(
            {
                "state": list(state),
                "committed": committed,
                "indicated": indicated,
                "kind": table.bet_kind(space, state, committed, indicated).value,
                "planned": planned,
                "expected": round(priced.expected(state, committed, indicated), 4),
            }
        )
    return {**out, "bets": rows}


def operator_delays(seed: int) -> np.random.Generator:
    """The generator of the indication delays of an operator seeded `seed` (a scenario's
    operator, `DelayedIndications`; its own stream: the answers draw from theirs)."""
    return np.random.default_rng(np.random.SeedSequence([seed, DELAY_STREAM]))


def delay_generator(seed: int, run: int = 0) -> np.random.Generator:
    """The generator of the indication delays of run `run` of an evaluation seeded `seed` (its
    own stream: the operator's answers draw from theirs)."""
    return np.random.default_rng(np.random.SeedSequence([seed, run, DELAY_STREAM]))


__all__ = [
    "ANTICIPATE",
    "DEFAULT_DELAYS",
    "INTERFACES",
    "MODES",
    "WAIT",
    "Bet",
    "DelayedIndications",
    "IndicationDelay",
    "Interaction",
    "InteractionCosts",
    "InteractionError",
    "Step",
    "bet_kind",
    "bet_summary",
    "delay_generator",
    "extra_seconds",
    "make_interaction",
    "operator_delays",
]
