"""The assembly MDP: the robot proposes a task, the operator may override it or misplace a part.

- **Actions** of a state are its feasible tasks (placements, then undo). Terminal states end the
  episode (absorbing); wrong and dead-end states offer only undo.
- **Mistakes**: a placement named in the spec's ``mistakes`` may end, with probability
  ``mistake_prob``, in another free seat of the same kind (7 -> 9 instead of 7 -> 10).
- **Overrides**: with probability ``override_prob`` the operator performs another feasible task
  of the state, uniformly, instead of the proposed one.
- **Rewards**: as published, -1 for every task and +2 on reaching a terminal state; or, with
  costs (seconds), -cost plus ``terminal_bonus``: per task token (``task_costs``) or per task
  edge, (state, task) -> seconds (``edge_costs``, e.g. a `hrc_drake.tasks.costs.CostTable` of
  the motion layer's planned durations plus the operator's bolting time).

Transitions are stored as flat arrays (edges = state-action pairs, outcomes per edge) so the
exact solver and the learner work on millions of states without per-state Python loops.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.tokens import UNDO

UNDO_INDEX = -1


class EdgeCosts(Protocol):
    """Seconds (or any cost) of each task edge: what a `CostTable` offers."""

    def seconds(self, state: tuple[str, ...], task: str) -> float:
        """Cost of `task` (a token or ``"undo"``) from `state` (its task sequence)."""
        ...


@dataclass(frozen=True)
class Rewards:
    """Reward model. Without `task_costs`: the paper's -1 per task, +2 on reaching a terminal.

    `task_costs` maps a task token to its cost (e.g. seconds); undo costs are looked up as
    ``"undo <token undone>"`` then ``"undo"``. `edge_costs` gives the cost of each (state, task)
    edge instead (a `CostTable`: the time of a task depends on what is in place); give one or
    the other. With costs, a task's reward is -cost, plus `terminal_bonus` on reaching a
    terminal state.
    """

    step: float = -1.0
    terminal: float = 2.0
    task_costs: Mapping[str, float] | None = None
    terminal_bonus: float = 0.0
    edge_costs: EdgeCosts | None = None

    def __post_init__(self):
        if self.task_costs is not None and self.edge_costs is not None:
            raise ValueError("give task_costs (per task) or edge_costs (per edge), not both")

    def cost_of(self, task: str, undone: str | None = None) -> float:
        """The cost of a task from the table; KeyError naming the task if it is missing."""
        assert self.task_costs is not None
        keys = [f"undo {undone}", UNDO] if task == UNDO else [task]
        for key in keys:
            if key in self.task_costs:
                return float(self.task_costs[key])
        raise KeyError(f"task cost table has no entry for {keys[0]!r}; add it (or 'undo')")


@dataclass(frozen=True)
class MdpConfig:
    """Discount, operator model and rewards of the assembly MDP."""

    gamma: float = 0.95
    mistake_prob: float = 0.05
    override_prob: float = 0.0
    rewards: Rewards = Rewards()

    def __post_init__(self):
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma}")
        for name in ("mistake_prob", "override_prob"):
            value = getattr(self, name)
            if not 0.0 <= value < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {value}")


@dataclass(frozen=True, eq=False)
class SequenceMDP:
    """State-action pairs ("edges") and their outcomes, as flat arrays.

    Edges of state s are ``edge_start[s] : edge_start[s+1]``; outcomes of edge e are
    ``out_start[e] : out_start[e+1]`` (next state, probability, reward, task performed).
    """

    space: StateSpace
    config: MdpConfig
    edge_start: np.ndarray
    edge_src: np.ndarray
    edge_task: np.ndarray  # token index, UNDO_INDEX for undo
    edge_dst: np.ndarray  # the intended next state
    out_start: np.ndarray
    out_dst: np.ndarray
    out_prob: np.ndarray
    out_reward: np.ndarray

    @property
    def n_edges(self) -> int:
        """Number of state-action pairs."""
        return len(self.edge_src)

    def task_name(self, edge: int) -> str:
        """The task token of an edge."""
        t = int(self.edge_task[edge])
        return UNDO if t == UNDO_INDEX else self.space.tokens[t]

    def edges_of(self, state: int) -> range:
        """Edge ids of a state's actions."""
        return range(int(self.edge_start[state]), int(self.edge_start[state + 1]))


def build_mdp(space: StateSpace, config: MdpConfig | None = None) -> SequenceMDP:
    """The MDP of a state space under an operator and reward model."""
    config = config or MdpConfig()
    n = space.n_states
    kind = space.kind
    children = np.arange(1, n)
    assembly_src = space.parent[children]
    undo_src = children[kind[children] != StateKind.TERMINAL]
    src = np.concatenate([assembly_src, undo_src])
    dst = np.concatenate([children, space.parent[undo_src]])
    task = np.concatenate([space.last[children], np.full(len(undo_src), UNDO_INDEX)])
    is_undo = np.concatenate([np.zeros(len(children), bool), np.ones(len(undo_src), bool)])
    order = np.lexsort((task, is_undo, src))
    src, dst, task, is_undo = src[order], dst[order], task[order], is_undo[order]
    edge_start = np.searchsorted(src, np.arange(n + 1)).astype(np.int64)

    # Mistakes: a placement may end in a sibling placement of the same (part, mount).
    table = space.table
    prone = np.zeros(len(table.mount_count), dtype=bool)
    mounts = list(space.spec.mounts)
    for part, to in space.spec.mistakes:
        prone[[i for i, m in enumerate(mounts) if m.part == part and m.on == to]] = True
    mount_of = np.where(is_undo, -1, table.mount[np.maximum(task, 0)])
    mistaken = ~is_undo & prone[np.maximum(mount_of, 0)] & (config.mistake_prob > 0)
    key = np.where(mistaken, src * len(prone) + mount_of, -1 - np.arange(len(src)))
    _, group, size = np.unique(key, return_inverse=True, return_counts=True)
    by_group = np.argsort(group, kind="stable")
    group_begin = np.concatenate(([0], np.cumsum(size)[:-1]))
    k = size[group]  # outcomes per edge
    edge_rep = np.repeat(np.arange(len(src)), k)
    within = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
    partner = by_group[np.repeat(group_begin[group], k) + within]
    same = partner == edge_rep
    prob = np.where(
        same, 1.0 - np.where(k > 1, config.mistake_prob, 0.0)[edge_rep], 0.0
    ) + np.where(~same, config.mistake_prob / np.maximum(k - 1, 1)[edge_rep], 0.0)
    out_order = np.lexsort((task[partner], edge_rep))
    edge_rep, partner, prob = edge_rep[out_order], partner[out_order], prob[out_order]
    out_dst = dst[partner]
    out_start = np.concatenate(([0], np.cumsum(k))).astype(np.int64)
    reward = _outcome_rewards(space, config.rewards, src[edge_rep], task[partner], out_dst)
    return SequenceMDP(
        space=space,
        config=config,
        edge_start=edge_start,
        edge_src=src,
        edge_task=task,
        edge_dst=dst,
        out_start=out_start,
        out_dst=out_dst,
        out_prob=prob,
        out_reward=reward,
    )


def _outcome_rewards(
    space: StateSpace, rewards: Rewards, src: np.ndarray, task: np.ndarray, dst: np.ndarray
) -> np.ndarray:
    terminal = space.kind[dst] == StateKind.TERMINAL
    if rewards.edge_costs is not None:
        return -_edge_costs(space, rewards.edge_costs, src, task) + np.where(
            terminal, rewards.terminal_bonus, 0.0
        )
    if rewards.task_costs is None:
        return np.where(terminal, rewards.terminal, rewards.step).astype(float)
    tokens = space.tokens
    cost = np.empty(len(src))
    for i, (s, t) in enumerate(zip(src.tolist(), task.tolist(), strict=True)):
        if t == UNDO_INDEX:
            cost[i] = rewards.cost_of(UNDO, tokens[space.last[s]])
        else:
            cost[i] = rewards.cost_of(tokens[t])
    return -cost + np.where(terminal, rewards.terminal_bonus, 0.0)


def _edge_costs(
    space: StateSpace, costs: EdgeCosts, src: np.ndarray, task: np.ndarray
) -> np.ndarray:
    tokens = space.tokens
    sequences: dict[int, tuple[str, ...]] = {}
    cached: dict[tuple[int, int], float] = {}
    out = np.empty(len(src))
    for i, (s, t) in enumerate(zip(src.tolist(), task.tolist(), strict=True)):
        if (s, t) not in cached:
            if s not in sequences:
                sequences[s] = space.sequence(s)
            cached[s, t] = float(
                costs.seconds(sequences[s], UNDO if t == UNDO_INDEX else tokens[t])
            )
        out[i] = cached[s, t]
    return out
