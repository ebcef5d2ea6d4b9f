"""Deciders: what the robot proposes at each task boundary, and what it learns from the answer.

A decider offers ``propose(state) -> task``, ``observe(state, proposed, performed)`` and
``reset()`` (forget what one run taught it, so that runs are independent and the same seeds give
the same report however runs are spread over processes). States are task sequences. Built-in:

- ``paper-q``: the greedy policy of tabular Q-learning with the paper's schedule (`PaperSchedule`,
  seeded), unit rewards; fixed during a run.
- ``exact``: the exact minimum-effort policy (unit costs, `exact_policy`).
- ``time``: the exact policy in expected seconds (`exact_policy(space, costs=table)`).
- ``mpc``: model-predictive. It keeps an `OnlineOperatorModel` and at every boundary re-solves
  the expected seconds to finish over the states below the current one (the fixed point of
  value iteration, reached by sweeps up and down the levels of that subtree, see
  `MpcDecider.q_values`), warm started from its previous values; proposing task a in state s
  leads to the successor of the task performed, with the model's probabilities. The undo of the
  current state leads above it: that value is held at its last estimate (the receding horizon
  is the subtree).
- ``worst-case``: min-max. The robot proposes the task that minimises the longest completion
  time over the operator's possible answers: following, or one of the spec's ``mistakes``
  alternatives of the proposal. The adversary is bounded: overrides are excluded (an operator
  who may override forever never finishes, so every policy's worst case would be infinite), and
  it makes at most `mistakes` misplacements per run (for the same reason: it could misplace the
  same part after every undo).

Every answer other than the proposal costs `deviation_seconds` on top of the task's time in the
models of `mpc` and `worst-case` (and in `hrc_drake.evaluate`): the robot, already moving toward
the proposed task, stops and returns. 1 s is our figure; nothing is published.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from hrc_drake.paths import UsageError
from hrc_drake.tasks.costs import CostTable
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.learn import PaperSchedule, train
from hrc_drake.tasks.mdp import UNDO_INDEX, MdpConfig, SequenceMDP, build_mdp
from hrc_drake.tasks.operator_model import OnlineOperatorModel
from hrc_drake.tasks.policy import Policy, policy_from_choices
from hrc_drake.tasks.solve import exact_policy, solve_exact, timed_config

DEVIATION_SECONDS = 1.0


class Decider(Protocol):
    """Proposes a task at each boundary; observes what the operator performed."""

    name: str

    def propose(self, state: tuple[str, ...]) -> str:
        """The task to propose in `state` (not terminal)."""
        ...

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """What happened after proposing `proposed` in `state`."""
        ...

    def reset(self) -> None:
        """Forget what the current run taught."""
        ...


class PolicyDecider:
    """Looks a fixed policy up; learns nothing."""

    def __init__(self, name: str, policy: Policy):
        self.name = name
        self.policy = policy

    def propose(self, state: tuple[str, ...]) -> str:
        """The policy's task in `state`."""
        return self.policy.next_task(state)

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """Nothing to learn."""

    def reset(self) -> None:
        """Nothing to forget."""


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


def _unit_mdp(space: StateSpace, costs: CostTable, mistake_prob: float) -> SequenceMDP:
    return build_mdp(space, timed_config(costs, MdpConfig(gamma=1.0, mistake_prob=mistake_prob)))


class MpcDecider:
    """Re-solves expected seconds from the current state under the online operator model."""

    name = "mpc"

    def __init__(
        self,
        space: StateSpace,
        costs: CostTable,
        deviation_seconds: float = DEVIATION_SECONDS,
        follow_prior: float = 4.0,
        other_prior: float = 0.05,
        tolerance: float = 1e-7,
    ):
        self.space = space
        self.deviation = float(deviation_seconds)
        self.follow_prior, self.other_prior = follow_prior, other_prior
        self.tolerance = tolerance
        mdp = _unit_mdp(space, costs, 0.0)
        self.mdp = mdp
        self.cost = -mdp.out_reward  # one outcome per edge without mistakes
        n = space.n_states
        # States that offer only undo (wrong, dead end): worth their undo plus their parent.
        self.only_undo = (space.n_children == 0) & (space.kind != StateKind.TERMINAL)
        self.only_undo[0] = False
        self.is_undo = (mdp.edge_task == UNDO_INDEX).astype(float)
        self.child = np.where(self.is_undo > 0, n, mdp.edge_dst)  # slot n: 0 + 0 * V
        self.initial = -solve_exact(_unit_mdp(space, costs, 0.05)).values
        self.solve_seconds: list[float] = []
        self._layouts: dict[int, tuple] = {}
        self.reset()

    def reset(self) -> None:
        """A fresh operator model and the initial values."""
        self.model = OnlineOperatorModel(self.space, self.follow_prior, self.other_prior)
        n = self.space.n_states
        self.values = np.append(self.initial, 0.0)
        self.alpha = np.append(
            np.where(self.space.kind == StateKind.TERMINAL, 0.0, self.initial), 0.0
        )
        self.beta = np.zeros(n + 1)
        self.alpha[:n][self.only_undo] = self.cost[self.mdp.edge_start[:-1][self.only_undo]]
        self.beta[:n][self.only_undo] = 1.0

    def observe(self, state: tuple[str, ...], proposed: str, performed: str) -> None:
        """Update the operator model."""
        self.model.update(state, proposed, performed)

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
        values, alpha, beta = self.values, self.alpha, self.beta
        layout = self._layouts.get(state)
        if layout is None:
            if len(self._layouts) >= 4096:
                self._layouts.clear()
            layout = self._layouts[state] = self._layout(state)
        levels, states, k, edges, seg, rep, cost, child, up, parent, follow, other, wrong = layout
        fix_pos, fix_col, fix_prob, fix_seg, fix_pen = self._corrections(states, seg)

        def mix(x, lseg, lrep, es, fix):
            """Expected value of x over the answers to each proposal."""
            out = follow[es] * x + other[es] * (np.add.reduceat(x, lseg)[lrep] - x)
            fpos, fcol, fprob, fseg, _ = fix
            if len(fpos):
                out[fpos] = np.add.reduceat(fprob * x[fcol], fseg)
            return out

        bounds, s0 = [], 0
        for lv in levels:
            s1 = s0 + len(lv)
            if s1 > s0:
                e0 = int(seg[s0])
                e1 = int(seg[s1]) if s1 < len(states) else len(edges)
                f0, f1 = np.searchsorted(fix_pos, [e0, e1])
                c0 = int(fix_seg[f0]) if f0 < len(fix_seg) else len(fix_col)
                c1 = int(fix_seg[f1]) if f1 < len(fix_seg) else len(fix_col)
                es, lseg, lrep = slice(e0, e1), seg[s0:s1] - e0, rep[e0:e1] - s0
                fix = (
                    fix_pos[f0:f1] - e0,
                    fix_col[c0:c1] - e0,
                    fix_prob[c0:c1],
                    fix_seg[f0:f1] - c0,
                    fix_pen[f0:f1],
                )
                pen = self.deviation * (1.0 - follow[es])
                if len(fix[0]):
                    pen[fix[0]] = fix[4]
                c = mix(up[es], lseg, lrep, es, fix)
                bounds.append([lv, es, lseg, lrep, fix, pen, c, None, None])
            s0 = s1

        def settle(level, a, gain):
            """Values and lines of a level's states from their q-lines at the parents' values."""
            lv, es, lseg, lrep, _, _, c = level[:7]
            cand = (a + c * values[parent[es]]) * gain
            best = np.minimum.reduceat(cand, lseg)
            pos = np.arange(len(cand))
            arg = np.minimum.reduceat(np.where(cand <= best[lrep], pos, len(cand)), lseg)
            alpha[lv], beta[lv] = a[arg] * gain[arg], c[arg] * gain[arg]
            change = float(np.max(np.abs(best - values[lv])))
            values[lv] = best
            return change

        for _ in range(100_000):
            change = 0.0
            for level in reversed(bounds):
                lv, es, lseg, lrep, fix, pen, c = level[:7]
                a = mix(cost[es] + alpha[child[es]], lseg, lrep, es, fix) + pen
                b = mix(beta[child[es]], lseg, lrep, es, fix)
                level[7], level[8] = a, 1.0 / np.maximum(1.0 - b, 1e-12)
                change = max(change, settle(level, a, level[8]))
            for level in bounds[1:]:
                change = max(change, settle(level, level[7], level[8]))
            if change < self.tolerance:
                break
        _, es, *_, c, a, gain = bounds[0]  # the current state
        q = a + (1.0 - 1.0 / gain) * values[state] + c * values[parent[es]]
        values[wrong] = alpha[wrong] + values[self.space.parent[wrong]]
        self.solve_seconds.append(time.perf_counter() - start)
        return edges[: k[0]], q

    def _layout(self, state: int) -> tuple:
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
        return levels, states, k, edges, seg, rep, cost, child, up, parent, pf / z, po / z, wrong

    def _corrections(self, states: np.ndarray, seg: np.ndarray):
        """The proposals of the observed states in the subtree (`states`, ascending), as flat
        arrays: each proposal's edge position (ascending), the positions of the answers and
        their probabilities (proposal i's answers from ``start[i]``), and the expected
        deviation cost."""
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
                pen.append(self.deviation * (1.0 - p[a]))
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


class WorstCaseDecider:
    """Min-max over following and at most `mistakes` misplacements per run (see module doc)."""

    name = "worst-case"

    def __init__(
        self,
        space: StateSpace,
        costs: CostTable,
        deviation_seconds: float = DEVIATION_SECONDS,
        mistakes: int = 2,
    ):
        self.space = space
        self.budget = int(mistakes)
        mdp = _unit_mdp(space, costs, 0.5)  # outcomes = the proposal and its mistake seats
        self.mdp = mdp
        out_edge = np.repeat(np.arange(mdp.n_edges), np.diff(mdp.out_start))
        self.deviates = mdp.out_dst != mdp.edge_dst[out_edge]
        self.out_cost = -mdp.out_reward + float(deviation_seconds) * self.deviates
        self.levels = self._solve()
        self.reset()

    def _solve(self) -> list[np.ndarray]:
        mdp = self.mdp
        n = self.space.n_states
        has = np.diff(mdp.edge_start) > 0
        seg_e = mdp.edge_start[:-1][has]
        levels: list[np.ndarray] = []
        below = None
        for _ in range(self.budget + 1):
            w = np.zeros(n) if below is None else below.copy()
            for _sweep in range(10 * n + 10):
                nxt = w[mdp.out_dst]
                if below is None:
                    # No mistake left: the operator follows.
                    val = np.where(self.deviates, -np.inf, self.out_cost + nxt)
                else:
                    val = self.out_cost + np.where(self.deviates, below[mdp.out_dst], nxt)
                q = np.maximum.reduceat(val, mdp.out_start[:-1])
                new = np.zeros(n)
                new[has] = np.minimum.reduceat(q, seg_e)
                if np.array_equal(new, w):
                    break
                w = new
            levels.append(w)
            below = w
        return levels

    def reset(self) -> None:
        """A full budget of mistakes."""
        self.left = self.budget

    def q_values(self, state: int, left: int) -> tuple[range, np.ndarray]:
        """Edges of `state` and their worst completion seconds with `left` mistakes to come."""
        mdp = self.mdp
        edges = mdp.edges_of(state)
        w = self.levels[left]
        below = self.levels[left - 1] if left > 0 else None
        q = []
        for e in edges:
            lo, hi = int(mdp.out_start[e]), int(mdp.out_start[e + 1])
            vals = [
                self.out_cost[o]
                + (below[mdp.out_dst[o]] if self.deviates[o] else w[mdp.out_dst[o]])
                for o in range(lo, hi)
                if below is not None or not self.deviates[o]
            ]
            q.append(max(vals))
        return edges, np.array(q)

    def propose(self, state: tuple[str, ...]) -> str:
        """The task of least worst-case completion seconds."""
        edges, q = self.q_values(self.space.index(state), self.left)
        best = int(np.flatnonzero(q <= q.min() + 1e-9)[0])
        return self.mdp.task_name(edges[best])

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
    deviation_seconds: float = DEVIATION_SECONDS,
):
    """The decider `name` for `space` with the cost table `costs`; UsageError naming the known
    deciders if `name` is unknown."""
    if name == "paper-q":
        return PolicyDecider(name, paper_q_policy(space, seed))
    if name == "exact":
        return PolicyDecider(name, exact_policy(space))
    if name == "time":
        return PolicyDecider(name, exact_policy(space, costs=costs))
    if name == "mpc":
        return MpcDecider(space, costs, deviation_seconds)
    if name == "worst-case":
        return WorstCaseDecider(space, costs, deviation_seconds)
    raise UsageError(f"unknown decider {name!r}; known deciders: {', '.join(DECIDERS)}")
