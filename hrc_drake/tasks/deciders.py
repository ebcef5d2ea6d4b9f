"""Deciders: what the robot proposes at each task boundary, whether it starts on a prediction,
and what it learns from the answer.

A decider offers ``propose(state) -> task``, ``commit(state, proposal) -> task or None`` (the
placement the robot starts on before the operator's indication, or None to wait for it; see
`hrc_drake.tasks.interaction`), ``observe(state, proposed, performed)``, ``reset()`` (forget what
one run taught it, so that runs are independent and the same seeds give the same report however
runs are spread over processes) and ``start_run()`` (a new assembly by the same operator: forget
the run, keep the operator model). States are task sequences. Built-in:

- ``paper-q``: the greedy policy of tabular Q-learning with the paper's schedule (`PaperSchedule`,
  seeded), unit rewards; fixed during a run.
- ``exact``: the exact minimum-effort policy (unit costs, `exact_policy`).
- ``time``: the exact policy in expected seconds (`exact_policy(space, costs=table)`).
- ``mpc``: model-predictive. It keeps an `OnlineOperatorModel` and at every boundary re-solves
  the expected seconds to finish over the states below the current one (the fixed point of
  value iteration, reached by sweeps up and down the levels of that subtree, see
  `hrc_drake.tasks.mpc`), warm started from its previous values; proposing task a in state s
  leads to the successor of the task performed, with the model's probabilities. The undo of the
  current state leads above it: that value is held at its last estimate (the receding horizon
  is the subtree).
- ``worst-case``: min-max. The robot proposes the task that minimises the longest completion
  time over the operator's possible answers: following, or one of the spec's ``mistakes``
  alternatives of the proposal. The adversary is bounded: overrides are excluded (an operator
  who may override forever never finishes, so every policy's worst case would be infinite), and
  it makes at most `mistakes` misplacements per run (for the same reason: it could misplace the
  same part after every undo).

The interaction (`Interaction`: mode, interface, indication delay) prices each boundary: in
``wait`` mode the delay; in ``anticipate`` mode the bet's expected seconds (`InteractionCosts`).
A bet is on the proposal (the robot does not move toward another task than the interface
shows). `paper-q` and `exact` always commit to their proposal (a placement; they wait for an
undo). `time`, `mpc` and `worst-case` weigh the bet by expected seconds under their operator
model — `time` the MDP's 5 % mistakes, `mpc` its online model, `worst-case` the worst answer —
commit or wait, whichever is cheaper, and include that price in choosing what to propose.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hrc_drake.paths import UsageError
from hrc_drake.tasks.adversary import worst_case_levels, worst_case_q
from hrc_drake.tasks.costs import CostTable
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.interaction import Interaction, InteractionCosts
from hrc_drake.tasks.learn import PaperSchedule, train
from hrc_drake.tasks.mdp import UNDO_INDEX, MdpConfig, SequenceMDP, build_mdp
from hrc_drake.tasks.mpc import MpcDecider, seconds_mdp
from hrc_drake.tasks.operator_model import OnlineOperatorModel
from hrc_drake.tasks.policy import Policy, policy_from_choices
from hrc_drake.tasks.solve import exact_policy, solve_exact
from hrc_drake.tasks.tokens import UNDO


def commit_to_proposal(interaction: Interaction | None, proposal: str) -> str | None:
    """The bet of a decider without an operator model: its proposal when the robot may
    anticipate and the proposal is a placement; else None (wait)."""
    if interaction is not None and not interaction.anticipates:
        return None
    return None if proposal == UNDO else proposal


class PolicyDecider:
    """Looks a fixed policy up and commits to its proposal (in ``anticipate`` mode); learns
    nothing."""

    def __init__(self, name: str, policy: Policy, interaction: Interaction | None = None):
        self.name = name
        self.policy = policy
        self.interaction = interaction or Interaction()

    def propose(self, state: tuple[str, ...]) -> str:
        """The policy's task in `state`."""
        return self.policy.next_task(state)

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The proposal, when it is a placement and the robot may anticipate."""
        return commit_to_proposal(self.interaction, proposal)

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """Nothing to learn."""

    def reset(self) -> None:
        """Nothing to forget."""

    def start_run(self) -> None:
        """Nothing to forget."""


def outcome_probabilities(mdp: SequenceMDP, edge: int) -> dict[str, float]:
    """The MDP's probability of each task performed when the edge's task is proposed."""
    out: dict[str, float] = {}
    dst = {int(d): t for t, d in mdp.space.tasks(int(mdp.edge_src[edge]))}
    for o in range(int(mdp.out_start[edge]), int(mdp.out_start[edge + 1])):
        task = dst[int(mdp.out_dst[o])]
        out[task] = out.get(task, 0.0) + float(mdp.out_prob[o])
    return out


def priced_mdp(mdp: SequenceMDP, bets: InteractionCosts) -> tuple[SequenceMDP, np.ndarray]:
    """`mdp` with each edge's reward lowered by its best bet's expected seconds under the MDP's
    own answer probabilities; and those seconds per edge."""
    price = np.zeros(mdp.n_edges)
    for e in range(mdp.n_edges):
        state = mdp.space.sequence(int(mdp.edge_src[e]))
        price[e] = bets.best_bet(state, outcome_probabilities(mdp, e), mdp.task_name(e))[1]
    out_edge = np.repeat(np.arange(mdp.n_edges), np.diff(mdp.out_start))
    return replace(mdp, out_reward=mdp.out_reward - price[out_edge]), price


class TimeDecider(PolicyDecider):
    """The exact policy in expected seconds, the interaction priced in, under the MDP's model of
    the operator (`mistake_prob` misplacements, 5 % for `time`); it commits to the best bet
    under that model. `solution` holds the MDP's values (expected seconds to finish)."""

    def __init__(
        self,
        space: StateSpace,
        costs: CostTable,
        interaction: Interaction | None = None,
        mistake_prob: float = 0.05,
        name: str = "time",
    ):
        self.bets = InteractionCosts(space, costs, interaction or Interaction())
        mdp, _ = priced_mdp(seconds_mdp(space, costs, mistake_prob), self.bets)
        self.mdp = mdp
        self.solution = solve_exact(mdp)
        meta = {
            "gamma": 1.0,
            "mistake_prob": mistake_prob,
            "interaction": self.bets.interaction.mode,
        }
        policy = policy_from_choices(mdp, self.solution.choice, "exact/time", meta)
        super().__init__(name, policy)
        self.interaction = self.bets.interaction

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The best bet on the proposal's answers under the MDP's model."""
        s = self.mdp.space.index(tuple(state))
        names = [t for t, _ in self.mdp.space.tasks(s)]
        edge = self.mdp.edges_of(s)[names.index(proposal)]
        probabilities = outcome_probabilities(self.mdp, edge)
        return self.bets.best_bet(tuple(state), probabilities, proposal)[0]


class WorstCaseDecider:
    """Min-max over following and at most `mistakes` misplacements per run (see module doc).

    In ``anticipate`` mode each proposal is priced twice, committing to it (a misplacement then
    costs the re-target's expected seconds) and waiting (the expected delay), and the cheaper
    worst case counts; the delay is taken at its expectation (it is not the adversary's). The
    min-max backup and its value iteration are `hrc_drake.tasks.adversary`'s (the same game in
    tasks there)."""

    name = "worst-case"

    def __init__(
        self,
        space: StateSpace,
        costs: CostTable,
        interaction: Interaction | None = None,
        mistakes: int = 2,
    ):
        self.space = space
        self.budget = int(mistakes)
        self.bets = InteractionCosts(space, costs, interaction or Interaction())
        self.interaction = self.bets.interaction
        mdp = seconds_mdp(space, costs, 0.5)  # outcomes = the proposal and its mistake seats
        self.mdp = mdp
        out_edge = np.repeat(np.arange(mdp.n_edges), np.diff(mdp.out_start))
        self.deviates = mdp.out_dst != mdp.edge_dst[out_edge]
        base = -mdp.out_reward
        self.out_cost = (base + self.bets.wait_seconds, base + self._commit_prices(out_edge))
        self.levels = worst_case_levels(mdp, self.out_cost, self.deviates, self.budget)
        self.reset()

    def _commit_prices(self, out_edge: np.ndarray) -> np.ndarray:
        """Per outcome, the expected seconds of having committed to the edge's task (inf where
        the robot cannot commit: an undo, or the ``wait`` mode)."""
        mdp, space = self.mdp, self.space
        price = np.full(len(mdp.out_dst), np.inf)
        for e in np.flatnonzero(mdp.edge_task != UNDO_INDEX):
            src = int(mdp.edge_src[e])
            committed = mdp.task_name(int(e))
            if committed not in self.bets.bets(space.sequence(src)):
                continue
            task_of = {int(d): t for t, d in space.tasks(src)}
            for o in range(int(mdp.out_start[e]), int(mdp.out_start[e + 1])):
                indicated = task_of[int(mdp.out_dst[o])]
                price[o] = self.bets.expected(space.sequence(src), committed, indicated)
        return price

    def _worst(self, w: np.ndarray, below: np.ndarray | None) -> np.ndarray:
        """Per edge, the worst completion seconds of its cheaper bet, with `w` the values with
        the same mistakes left and `below` with one fewer (None: no mistake left)."""
        return worst_case_q(self.mdp, self.out_cost, self.deviates, w, below)

    def reset(self) -> None:
        """A full budget of mistakes."""
        self.left = self.budget

    def start_run(self) -> None:
        """A new assembly: a full budget of mistakes again."""
        self.reset()

    def q_values(self, state: int, left: int) -> tuple[range, np.ndarray]:
        """Edges of `state` and their worst completion seconds with `left` mistakes to come."""
        below = self.levels[left - 1] if left > 0 else None
        edges = self.mdp.edges_of(state)
        return edges, self._worst(self.levels[left], below)[edges.start : edges.stop]

    def propose(self, state: tuple[str, ...]) -> str:
        """The task of least worst-case completion seconds."""
        edges, q = self.q_values(self.space.index(state), self.left)
        best = int(np.flatnonzero(q <= q.min() + 1e-9)[0])
        return self.mdp.task_name(edges[best])

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The proposal when committing to it has the smaller worst case; else None (wait)."""
        s = self.space.index(tuple(state))
        names = [t for t, _ in self.space.tasks(s)]
        e = self.mdp.edges_of(s)[names.index(proposal)]
        lo, hi = int(self.mdp.out_start[e]), int(self.mdp.out_start[e + 1])
        w = self.levels[self.left]
        below = self.levels[self.left - 1] if self.left > 0 else None
        worst = []
        for cost in self.out_cost:
            vals = [
                cost[o]
                + (below[self.mdp.out_dst[o]] if self.deviates[o] else w[self.mdp.out_dst[o]])
                for o in range(lo, hi)
                if below is not None or not self.deviates[o]
            ]
            worst.append(max(vals))
        return proposal if worst[1] <= worst[0] + 1e-9 and np.isfinite(worst[1]) else None

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """A misplacement uses one mistake of the budget."""
        if performed != proposed and self.left > 0:
            s = self.space.index(state)
            names = [t for t, _ in self.space.tasks(s)]
            e = self.mdp.edges_of(s)[names.index(proposed)]
            seats = self.mdp.out_dst[self.mdp.out_start[e] : self.mdp.out_start[e + 1]]
            if dict(self.space.tasks(s))[performed] in seats:
                self.left -= 1


def paper_q_policy(space: StateSpace, seed: int = 0) -> Policy:
    """The greedy policy of Q-learning with the paper's schedule (unit rewards, seeded)."""
    mdp = build_mdp(space, MdpConfig())
    result = train(mdp, PaperSchedule(), seed=seed)
    return policy_from_choices(mdp, result.choice, "paper-q", {"episodes": result.episodes})


DECIDERS = ("paper-q", "exact", "time", "mpc", "worst-case")


def make_decider(
    name: str,
    space: StateSpace,
    costs: CostTable,
    seed: int = 0,
    interaction: Interaction | None = None,
    model: OnlineOperatorModel | None = None,
):
    """The decider `name` for `space` with the cost table `costs` under `interaction` (default:
    anticipate, pointer); `mpc` starts from the operator model `model` (an operator profile)
    when given. UsageError naming the known deciders if `name` is unknown."""
    if name not in DECIDERS:
        raise UsageError(f"unknown decider {name!r}; known deciders: {', '.join(DECIDERS)}")
    interaction = interaction or Interaction()
    if name == "paper-q":
        return PolicyDecider(name, paper_q_policy(space, seed), interaction)
    if name == "exact":
        return PolicyDecider(name, exact_policy(space), interaction)
    if name == "time":
        return TimeDecider(space, costs, interaction)
    if name == "mpc":
        return MpcDecider(space, costs, interaction, model=model)
    return WorstCaseDecider(space, costs, interaction)
