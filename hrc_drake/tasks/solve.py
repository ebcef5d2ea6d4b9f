"""Exact solutions of the assembly MDP.

- `tasks_to_finish`: the fewest tasks (undo counted) from every state to a terminal state — the
  bar for "minimum effort". Two vectorised passes over the sequence tree: bottom-up (best way
  down through a state's children), then top-down (or first undo to the parent).
- `solve_exact`: value iteration on the stochastic MDP (mistakes, overrides, any rewards), one
  sparse matrix-vector product per sweep. Greedy choices break ties within `tie_tolerance` in
  the spec's canonical task order, so the same spec always gives the same policy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.mdp import EdgeCosts, MdpConfig, Rewards, SequenceMDP, build_mdp
from hrc_drake.tasks.policy import Policy, policy_from_choices

UNREACHABLE = np.iinfo(np.int64).max // 4


def tasks_to_finish(space: StateSpace) -> np.ndarray:
    """Fewest tasks from each state to a terminal state (undo counted as a task)."""
    n = space.n_states
    down = np.where(space.kind == StateKind.TERMINAL, 0, UNREACHABLE).astype(np.int64)
    for depth in range(int(space.depth.max()), 0, -1):
        states = np.flatnonzero(space.depth == depth)
        np.minimum.at(down, space.parent[states], down[states] + 1)
    best = down.copy()
    for depth in range(1, int(space.depth.max()) + 1):
        states = np.flatnonzero(space.depth == depth)
        best[states] = np.minimum(best[states], best[space.parent[states]] + 1)
    best[best >= UNREACHABLE] = -1
    assert len(best) == n
    return best


@dataclass(frozen=True, eq=False)
class Solution:
    """Values of states and state-action pairs, and the greedy edge of each state (-1: none)."""

    mdp: SequenceMDP
    values: np.ndarray
    q: np.ndarray
    choice: np.ndarray
    iterations: int


def q_from_values(mdp: SequenceMDP, values: np.ndarray) -> np.ndarray:
    """One Bellman backup: expected reward plus discounted next value, for every edge."""
    weighted = mdp.out_prob * (mdp.out_reward + mdp.config.gamma * values[mdp.out_dst])
    q = np.add.reduceat(weighted, mdp.out_start[:-1]) if len(weighted) else np.zeros(0)
    p = mdp.config.override_prob
    if p > 0:
        counts = np.diff(mdp.edge_start)
        has = counts > 0
        totals = np.zeros(mdp.space.n_states)
        totals[has] = np.add.reduceat(q, mdp.edge_start[:-1][has])
        k = counts[mdp.edge_src]
        others = (totals[mdp.edge_src] - q) / np.maximum(k - 1, 1)
        q = np.where(k > 1, (1 - p) * q + p * others, q)
    return q


def state_values(mdp: SequenceMDP, q: np.ndarray) -> np.ndarray:
    """max over each state's actions; 0 where the episode ends."""
    values = np.zeros(mdp.space.n_states)
    has = np.diff(mdp.edge_start) > 0
    if len(q):
        values[has] = np.maximum.reduceat(q, mdp.edge_start[:-1][has])
    return values


def greedy_choice(mdp: SequenceMDP, q: np.ndarray, tie_tolerance: float = 1e-9) -> np.ndarray:
    """Per state, the first edge (canonical task order) whose value is within tolerance of best."""
    values = state_values(mdp, q)
    near_best = (
        q >= values[mdp.edge_src] - tie_tolerance * np.maximum(1.0, np.abs(values))[mdp.edge_src]
    )
    candidates = np.flatnonzero(near_best)
    states, first = np.unique(mdp.edge_src[candidates], return_index=True)
    choice = np.full(mdp.space.n_states, -1, dtype=np.int64)
    choice[states] = candidates[first]
    return choice


def solve_exact(
    mdp: SequenceMDP, tolerance: float = 1e-10, max_iterations: int = 100_000
) -> Solution:
    """Optimal values and the greedy policy by value iteration; RuntimeError if it stalls."""
    values = np.zeros(mdp.space.n_states)
    iterations = 0
    for _ in range(max_iterations):
        q = q_from_values(mdp, values)
        new = state_values(mdp, q)
        change = float(np.max(np.abs(new - values))) if len(new) else 0.0
        values = new
        iterations += 1
        if change < tolerance:
            break
    else:
        raise RuntimeError(
            f"value iteration did not converge in {max_iterations} sweeps (last change "
            f"{change:.3g}); with gamma = 1 every policy must reach a terminal state — use "
            "gamma < 1 or check the spec for states that cannot finish"
        )
    q = q_from_values(mdp, values)
    return Solution(mdp, values, q, greedy_choice(mdp, q), iterations)


def timed_config(costs: EdgeCosts, config: MdpConfig | None = None) -> MdpConfig:
    """`config` with every task's reward set to minus its seconds from `costs` (per edge).

    Without `config`: `MdpConfig` with gamma 1, so that the solver minimises the expected
    seconds to finish (undiscounted: a second later counts as much as a second now).
    """
    base = config or MdpConfig(gamma=1.0)
    return replace(
        base, rewards=Rewards(edge_costs=costs, terminal_bonus=base.rewards.terminal_bonus)
    )


def exact_policy(
    space: StateSpace, config: MdpConfig | None = None, costs: EdgeCosts | None = None
) -> Policy:
    """The exact policy of `space` under `config` (default MdpConfig()).

    Unit rewards give the minimum-effort policy; with `costs` (a `CostTable`, seconds per task
    edge) the fastest one in expected seconds (see `timed_config`; default gamma 1).
    """
    if costs is not None:
        config = timed_config(costs, config)
    mdp = build_mdp(space, config)
    solution = solve_exact(mdp)
    meta = {
        "gamma": mdp.config.gamma,
        "mistake_prob": mdp.config.mistake_prob,
        "iterations": solution.iterations,
    }
    method = "exact"
    if costs is not None:
        method = "exact/time"
        meta["cell_hash"] = getattr(costs, "cell_hash", None)
        if mdp.config.gamma == 1.0 and mdp.config.rewards.terminal_bonus == 0.0:
            meta["expected_seconds_from_start"] = -float(solution.values[0])
    return policy_from_choices(mdp, solution.choice, method, meta)
