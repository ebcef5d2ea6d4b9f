"""The model-predictive decider (``mpc``): at every task boundary it re-solves the expected
seconds to finish below the current state under its online model of the operator.

The re-solve is value iteration restricted to the subtree of the current state, reached by
sweeps up and down its levels (`MpcDecider.q_values`), warm started from the previous values;
the undo of the current state leads above it, whose value is held at its last estimate (the
receding horizon is the subtree). It is apart from `hrc_drake.tasks.deciders` (which builds it
by name) because that solve, with its per-level bookkeeping, is most of the decider's code.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hrc_drake.tasks.costs import CostTable
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.interaction import Interaction, InteractionCosts
from hrc_drake.tasks.mdp import UNDO_INDEX, MdpConfig, SequenceMDP, build_mdp
from hrc_drake.tasks.operator_model import OnlineOperatorModel
from hrc_drake.tasks.solve import solve_exact, timed_config


def seconds_mdp(space: StateSpace, costs: CostTable, mistake_prob: float) -> SequenceMDP:
    """The MDP in expected seconds (gamma 1, the cost table's times) with `mistake_prob`
    misplacements: what the time-aware deciders (`time`, `mpc`, `worst-case`) solve."""
    return build_mdp(space, timed_config(costs, MdpConfig(gamma=1.0, mistake_prob=mistake_prob)))


def _ranges(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Concatenation of ``range(start[i], start[i] + count[i])``."""
    total = int(count.sum())
    offsets = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    return np.repeat(start, count) + offsets


def subtree_levels(space: StateSpace, state: int) -> list[np.ndarray]:
    """`state` and every state below it (placements only), one array per depth, ids ascending."""
    levels, frontier = [np.array([state])], np.array([state])
    while True:
        frontier = _ranges(space.first_child[frontier], space.n_children[frontier])
        if not len(frontier):
            return levels
        levels.append(frontier)


class MpcDecider:
    """Re-solves expected seconds from the current state under the online operator model."""

    name = "mpc"

    def __init__(
        self,
        space: StateSpace,
        costs: CostTable,
        interaction: Interaction | None = None,
        follow_prior: float = 4.0,
        other_prior: float = 0.05,
        tolerance: float = 1e-7,
        model: OnlineOperatorModel | None = None,
    ):
        self.space = space
        self.bets = InteractionCosts(space, costs, interaction or Interaction())
        self.interaction = self.bets.interaction
        if model is not None:
            follow_prior, other_prior = model.follow_prior, model.other_prior
        self.follow_prior, self.other_prior = follow_prior, other_prior
        self.profile = None if model is None else model.copy()
        self.tolerance = tolerance
        mdp = seconds_mdp(space, costs, 0.0)
        self.mdp = mdp
        self.cost = -mdp.out_reward  # one outcome per edge without mistakes
        n = space.n_states
        # States that offer only undo (wrong, dead end): worth their undo plus their parent.
        self.only_undo = (space.n_children == 0) & (space.kind != StateKind.TERMINAL)
        self.only_undo[0] = False
        self.is_undo = (mdp.edge_task == UNDO_INDEX).astype(float)
        self.child = np.where(self.is_undo > 0, n, mdp.edge_dst)  # slot n: 0 + 0 * V
        self.initial = -solve_exact(seconds_mdp(space, costs, 0.05)).values
        self.prior_price = self._prior_prices()
        self.solve_seconds: list[float] = []
        self._layouts: dict[int, _Subtree] = {}
        self.reset()

    def _prior_prices(self) -> np.ndarray:
        """Per edge, the expected seconds of its best bet under the prior (a state not
        observed yet): the proposal followed with the follow weight, any other task with the
        other weight."""
        space, mdp, bets = self.space, self.mdp, self.bets
        price = np.full(mdp.n_edges, bets.wait_seconds)
        for s in np.flatnonzero((space.kind != StateKind.TERMINAL) & (space.n_children > 0)):
            names = [t for t, _ in space.tasks(int(s))]
            state = space.sequence(int(s))
            total = self.follow_prior + self.other_prior * (len(names) - 1)
            for e, proposed in zip(mdp.edges_of(int(s)), names, strict=True):
                probabilities = {
                    t: (self.follow_prior if t == proposed else self.other_prior) / total
                    for t in names
                }
                price[e] = bets.best_bet(state, probabilities, proposed)[1]
        return price

    def reset(self) -> None:
        """The operator model it started with (a fresh one, or the profile's) and the initial
        values."""
        if self.profile is not None:
            self.model = self.profile.copy()
        else:
            self.model = OnlineOperatorModel(self.space, self.follow_prior, self.other_prior)
        n = self.space.n_states
        self.values = np.append(self.initial, 0.0)
        self.alpha = np.append(
            np.where(self.space.kind == StateKind.TERMINAL, 0.0, self.initial), 0.0
        )
        self.beta = np.zeros(n + 1)
        first = self.mdp.edge_start[:-1][self.only_undo]
        self.alpha[:n][self.only_undo] = self.cost[first] + self.prior_price[first]
        self.beta[:n][self.only_undo] = 1.0

    def start_run(self) -> None:
        """A new assembly by the same operator: the model and the values are kept."""

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """Update the operator model."""
        self.model.update(state, proposed, performed)

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The best bet on the proposal's answers under the current operator model."""
        probabilities = self.model.outcome_probabilities(tuple(state), proposal)
        return self.bets.best_bet(tuple(state), probabilities, proposal)[0]

    def q_values(self, state: int) -> tuple[np.ndarray, np.ndarray]:
        """Re-solve below `state`; returns its edge ids and their expected seconds.

        Each state's value is kept as a line in its parent's value, ``V(s) = alpha + beta *
        V(parent)`` (the parent enters through undo, of the state or of a child that offers
        only undo). A sweep goes up the levels, deepest first: with the children's lines each
        q-value of a state is ``A + B * V(state) + C * V(parent)``, the best proposal at the
        parent's current value gives the state's line, and ``V = (A + C * V(parent)) / (1 - B)``
        solves the loop through the children exactly. It then comes down the levels, each state
        reading its parent's new value. It stops when a sweep changes no value by `tolerance`:
        the fixed point of value iteration, in a few sweeps (the lines are exact once no state
        changes its best proposal).
        """
        start = time.perf_counter()
        values, alpha = self.values, self.alpha
        sub = self._cached_layout(state)
        blocks = _level_blocks(sub, self._corrections(sub.states, sub.seg))
        self._sweep(blocks, sub)
        top = blocks[0]  # the current state
        q = top.a + (1.0 - 1.0 / top.gain) * values[state] + top.c * values[sub.parent[top.edges]]
        values[sub.wrong] = alpha[sub.wrong] + values[self.space.parent[sub.wrong]]
        self.solve_seconds.append(time.perf_counter() - start)
        return sub.edges[: sub.k[0]], q

    def _cached_layout(self, state: int) -> _Subtree:
        """`_layout(state)`, kept for the states re-solved from (at most 4096 of them)."""
        layout = self._layouts.get(state)
        if layout is None:
            if len(self._layouts) >= 4096:
                self._layouts.clear()
            layout = self._layouts[state] = self._layout(state)
        return layout

    def _sweep(self, blocks: list[_Level], sub: _Subtree) -> None:
        """Sweep up the levels (deepest first, each state's line from its children's) and down
        (each state at its parent's new value) until no value changes by `tolerance`."""
        values, alpha, beta = self.values, self.alpha, self.beta
        cost, child, parent = sub.cost, sub.child, sub.parent
        for _ in range(100_000):
            change = 0.0
            for level in reversed(blocks):
                es = level.edges
                a = level.mix(cost[es] + alpha[child[es]]) + level.price
                b = level.mix(beta[child[es]])
                level.a, level.gain = a, 1.0 / np.maximum(1.0 - b, 1e-12)
                change = max(change, level.settle(values, alpha, beta, parent))
            for level in blocks[1:]:
                change = max(change, level.settle(values, alpha, beta, parent))
            if change < self.tolerance:
                break

    def _layout(self, state: int) -> _Subtree:
        """What the re-solve below `state` needs that the operator model does not change: the
        swept states by level, their edges, the edges' costs, children, parents and prior
        answer probabilities, and the states that offer only undo."""
        mdp, space = self.mdp, self.space
        keep = (space.kind != StateKind.TERMINAL) & ~self.only_undo
        every = subtree_levels(space, state)
        levels = [every[0]] + [lv[keep[lv]] for lv in every[1:]]
        states = np.concatenate(levels)
        k = mdp.edge_start[states + 1] - mdp.edge_start[states]
        edges = _ranges(mdp.edge_start[states], k)
        seg = np.concatenate(([0], np.cumsum(k)[:-1]))
        rep = np.repeat(np.arange(len(states)), k)
        cost, child, up = self.cost[edges], self.child[edges], self.is_undo[edges]
        parent = space.parent[states[rep]]  # -1 (values[-1] is 0) for the empty base
        pf, po = self.follow_prior, self.other_prior
        z = (pf + po * (k - 1))[rep]
        wrong = [lv[self.only_undo[lv]] for lv in every[1:]]
        wrong = np.concatenate(wrong) if wrong else np.zeros(0, dtype=np.int64)
        prior = self.prior_price[edges]
        return _Subtree(
            levels,
            states,
            k,
            edges,
            seg,
            rep,
            cost,
            child,
            up,
            parent,
            pf / z,
            po / z,
            wrong,
            prior,
        )

    def _corrections(self, states: np.ndarray, seg: np.ndarray):
        """The proposals of the observed states in the subtree (`states`, ascending), as flat
        arrays: each proposal's edge position (ascending), the positions of the answers and
        their probabilities (proposal i's answers from ``start[i]``), and the price of its best
        bet."""
        pos, col, prob, start, pen = [], [], [], [], []
        n = 0
        for s in sorted(self.model.observed_states()):
            i = int(np.searchsorted(states, s))
            if i == len(states) or states[i] != s:
                continue
            lo = int(seg[i])
            names = [t for t, _ in self.space.tasks(s)]
            for a, proposed in enumerate(names):
                probs = self.model.outcome_probabilities(s, proposed)
                p = [probs[t] for t in names]
                pos.append(lo + a)
                col.extend(range(lo, lo + len(names)))
                prob.extend(p)
                start.append(n)
                pen.append(self.bets.best_bet(self.space.sequence(s), probs, proposed)[1])
                n += len(names)
        return (
            np.array(pos, dtype=np.int64),
            np.array(col, dtype=np.int64),
            np.array(prob, dtype=float),
            np.array(start, dtype=np.int64),
            np.array(pen, dtype=float),
        )

    def propose(self, state: tuple[str, ...]) -> str:
        """The task of least expected seconds to finish under the current model."""
        edges, q = self.q_values(self.space.index(state))
        best = int(np.flatnonzero(q <= q.min() + 1e-9)[0])
        return self.mdp.task_name(int(edges[best]))


@dataclass(frozen=True, eq=False)
class _Subtree:
    """What the re-solve below a state needs that the operator model does not change
    (`MpcDecider._layout`): the swept states by level (`levels`; `states` all of them, `k`
    their edge counts), their edges (`edges`; `seg` each state's first, `rep` each edge's
    state, as positions), the edges' costs, children, undo flags (`up`), parents and prior
    answer probabilities (`follow`, `other`) and bet prices (`prior`), and the states below
    that offer only undo (`wrong`)."""

    levels: list[np.ndarray]
    states: np.ndarray
    k: np.ndarray
    edges: np.ndarray
    seg: np.ndarray
    rep: np.ndarray
    cost: np.ndarray
    child: np.ndarray
    up: np.ndarray
    parent: np.ndarray
    follow: np.ndarray
    other: np.ndarray
    wrong: np.ndarray
    prior: np.ndarray


@dataclass(eq=False)
class _Level:
    """One level of the subtree being re-solved, as positions in the layout's flat arrays: its
    states (`states`, ids), their edges (`edges`, a slice), each state's first edge (`seg`) and
    each edge's state (`rep`) within the level, the answer probabilities of the proposals
    (`follow`, `other`; `fix` for the observed states, see `MpcDecider._corrections`), each
    edge's bet price (`price`) and the weight of the parent's value in each q-value (`c`). A
    sweep up sets the q-values' constant part `a` and the loop gain ``1 / (1 - B)`` (`gain`)."""

    states: np.ndarray
    edges: slice
    seg: np.ndarray
    rep: np.ndarray
    follow: np.ndarray
    other: np.ndarray
    fix: tuple
    price: np.ndarray
    c: np.ndarray | None = None
    a: np.ndarray | None = None
    gain: np.ndarray | None = None

    def mix(self, x: np.ndarray) -> np.ndarray:
        """Expected value of x over the answers to each proposal."""
        out = self.follow * x + self.other * (np.add.reduceat(x, self.seg)[self.rep] - x)
        fpos, fcol, fprob, fseg, _ = self.fix
        if len(fpos):
            out[fpos] = np.add.reduceat(fprob * x[fcol], fseg)
        return out

    def settle(
        self, values: np.ndarray, alpha: np.ndarray, beta: np.ndarray, parent: np.ndarray
    ) -> float:
        """Values and lines of the level's states from their q-lines at the parents' values;
        the largest change of a value."""
        a, gain, c, lv = self.a, self.gain, self.c, self.states
        cand = (a + c * values[parent[self.edges]]) * gain
        best = np.minimum.reduceat(cand, self.seg)
        pos = np.arange(len(cand))
        arg = np.minimum.reduceat(np.where(cand <= best[self.rep], pos, len(cand)), self.seg)
        alpha[lv], beta[lv] = a[arg] * gain[arg], c[arg] * gain[arg]
        change = float(np.max(np.abs(best - values[lv])))
        values[lv] = best
        return change


def _level_blocks(sub: _Subtree, corrections: tuple) -> list[_Level]:
    """The non-empty levels of the subtree, with the corrections of the observed states
    (`MpcDecider._corrections`) cut to each level."""
    states, edges, seg, rep, up, prior = sub.states, sub.edges, sub.seg, sub.rep, sub.up, sub.prior
    fix_pos, fix_col, fix_prob, fix_seg, fix_pen = corrections
    blocks, s0 = [], 0
    for lv in sub.levels:
        s1 = s0 + len(lv)
        if s1 > s0:
            e0 = int(seg[s0])
            e1 = int(seg[s1]) if s1 < len(states) else len(edges)
            f0, f1 = np.searchsorted(fix_pos, [e0, e1])
            c0 = int(fix_seg[f0]) if f0 < len(fix_seg) else len(fix_col)
            c1 = int(fix_seg[f1]) if f1 < len(fix_seg) else len(fix_col)
            es = slice(e0, e1)
            fix = (
                fix_pos[f0:f1] - e0,
                fix_col[c0:c1] - e0,
                fix_prob[c0:c1],
                fix_seg[f0:f1] - c0,
                fix_pen[f0:f1],
            )
            pen = prior[es].copy()
            if len(fix[0]):
                pen[fix[0]] = fix[4]
            lseg, lrep = seg[s0:s1] - e0, rep[e0:e1] - s0
            level = _Level(lv, es, lseg, lrep, sub.follow[es], sub.other[es], fix, pen)
            level.c = level.mix(up[es])
            blocks.append(level)
        s0 = s1
    return blocks
