"""Tabular Q-learning of the assembly MDP, with the paper's schedule and one that explores enough.

- `PaperSchedule`: every episode starts from the empty base; epsilon-greedy with epsilon 0.9
  decaying by 0.005 per episode; training stops on the 20-episode moving average of the return
  (once epsilon has decayed, when that average moved less than `stop_tolerance` over the last
  window). Learning rate and discount are not published: ours are parameters.
- `FullSchedule`: exploring starts — each sweep starts one episode from every (state, action)
  pair of every non-terminal state, in a seeded random order; per-pair learning rate 1/n**0.6
  so that the estimates settle under the operator's random mistakes; stops when the greedy
  values move less than `stop_tolerance` over a sweep.
- `CoverageSchedule` (the default, `hrc_drake.tasks.coverage`): rounds of exploring starts
  aimed where learning is not done (loops, changes, large or stale errors, noise sampled too
  little), vectorised over episodes; stops when full sweeps find no loop and change nothing.
  Minimum-effort from every state on specs from 20 to 820,427 states
  (benchmarks/reports/coverage.md).
- `ExploringStartsSchedule`: exploring starts over *states*, not pairs — each sweep starts one
  episode from every non-terminal state, deepest states first (their values are what the
  shallower ones bootstrap from), and opens it with the state's least-tried task; then greedy
  with epsilon0 / sweep (greedy in the limit); Q starts optimistic (at the largest one-step
  reward, so untried tasks look best); per-pair learning rate 1/n**0.6. Stops when the greedy
  task of every state has not changed for `patience` sweeps, or after `max_sweeps`. On the
  flange case it stops after a median of 88 episodes (at most 160), minimum-effort from every
  state for 100/100 seeds (benchmarks/reports/learning.md).

An *episode* starts in a state (the empty base for `PaperSchedule`, the exploring start for the
others), and ends on reaching a terminal state or after `max_steps` tasks; every task the
operator performs (an undo included) is one step. All schedules are seeded (same seed, same
Q-table) and return the learning curve (the discounted return of every episode).
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrc_drake.memory import give_back_free_memory
from hrc_drake.tasks.coverage import CoverageSchedule, train_coverage
from hrc_drake.tasks.mdp import SequenceMDP
from hrc_drake.tasks.solve import greedy_choice, state_values

Progress = Callable[[int, int, float], None]  # (episode, total or 0, last return)


@dataclass(frozen=True)
class PaperSchedule:
    """The published schedule (section 6) plus our choices where the paper is silent."""

    epsilon0: float = 0.9
    epsilon_decay: float = 0.005
    epsilon_min: float = 0.0
    alpha: float = 0.1
    window: int = 20
    stop_tolerance: float = 0.05
    max_episodes: int = 5000
    max_steps: int = 100
    name: str = "paper"


@dataclass(frozen=True)
class FullSchedule:
    """Exploring starts from every non-terminal (state, action) pair, sweep after sweep."""

    epsilon: float = 0.1
    alpha_power: float = 0.6
    min_sweeps: int = 30
    max_sweeps: int = 2000
    stop_tolerance: float = 0.01
    max_steps: int = 100
    name: str = "full"


@dataclass(frozen=True)
class ExploringStartsSchedule:
    """One episode from every non-terminal state per sweep, least-tried task first, then greedy.

    `epsilon0 / sweep` is the chance of a random task after the first; `optimistic` starts Q at
    the largest one-step reward of the MDP (an upper bound of every value when only reaching a
    terminal state pays a positive reward, as with the paper's rewards and with time costs).
    """

    epsilon0: float = 0.3
    alpha_power: float = 0.6
    optimistic: bool = True
    patience: int = 2
    min_sweeps: int = 3
    max_sweeps: int = 10
    max_steps: int = 100
    name: str = "explore"


Schedule = PaperSchedule | FullSchedule | ExploringStartsSchedule | CoverageSchedule
SCHEDULES = {
    s.name: s for s in (CoverageSchedule, PaperSchedule, FullSchedule, ExploringStartsSchedule)
}
DEFAULT_SCHEDULE = CoverageSchedule.name


@dataclass(frozen=True, eq=False)
class LearningResult:
    """The learned Q-table (one value per MDP edge), its greedy choices and learning curve.

    `returns` is the return of every episode, except for `CoverageSchedule`, whose episodes run
    by the million: there it is the mean return of each round's episodes. `converged` is False
    when a schedule with a stop rule reached its cap instead (`CoverageSchedule.max_rounds`).
    """

    q: np.ndarray
    choice: np.ndarray
    returns: np.ndarray
    episodes: int
    steps: int
    wall_time: float
    schedule: str
    seed: int
    rounds: int = 0
    converged: bool = True

    def moving_average(self, window: int = 20) -> np.ndarray:
        """Mean return over the last `window` episodes, at every episode."""
        r = self.returns
        c = np.cumsum(np.insert(r, 0, 0.0))
        lo = np.maximum(np.arange(1, len(r) + 1) - window, 0)
        return (c[1:] - c[lo]) / (np.arange(1, len(r) + 1) - lo)


class _Simulator:
    """Samples the MDP: operator overrides, then the outcome (mistakes) of the task performed."""

    def __init__(self, mdp: SequenceMDP, rng: random.Random):
        self.rng = rng
        self.edge_start = mdp.edge_start.tolist()
        self.out_start = mdp.out_start.tolist()
        self.out_dst = mdp.out_dst.tolist()
        # Cumulative outcome probabilities within each edge, for inverse-CDF sampling.
        cum = np.cumsum(mdp.out_prob)
        before = np.concatenate(([0.0], cum))[mdp.out_start[:-1]]
        self.out_cum = (cum - np.repeat(before, np.diff(mdp.out_start))).tolist()
        self.out_reward = mdp.out_reward.tolist()
        self.override = mdp.config.override_prob

    def step(self, state: int, edge: int) -> tuple[int, float]:
        rng = self.rng
        lo, hi = self.edge_start[state], self.edge_start[state + 1]
        if self.override > 0 and hi - lo > 1 and rng.random() < self.override:
            other = lo + rng.randrange(hi - lo - 1)
            edge = other + 1 if other >= edge else other
        u = rng.random()
        o, last = self.out_start[edge], self.out_start[edge + 1] - 1
        while o < last and u >= self.out_cum[o]:
            o += 1
        return self.out_dst[o], self.out_reward[o]


def _greedy_edge(q: list[float], lo: int, hi: int, rng: random.Random) -> int:
    best = max(q[lo:hi])
    ties = [e for e in range(lo, hi) if q[e] == best]
    return ties[0] if len(ties) == 1 else rng.choice(ties)


def train(
    mdp: SequenceMDP,
    schedule: Schedule | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> LearningResult:
    """Learn a Q-table for `mdp` with `schedule` (default: `CoverageSchedule()`, as `hrc-drake
    train`); seeded, so the same seed gives the same table."""
    start = time.perf_counter()
    if schedule is None:
        schedule = SCHEDULES[DEFAULT_SCHEDULE]()
    if isinstance(schedule, CoverageSchedule):
        # Free pages back first (building the MDP leaves many), then its batches' pages.
        give_back_free_memory()
        outcome = train_coverage(mdp, schedule, seed=seed, progress=progress)
        give_back_free_memory()
        return LearningResult(
            q=outcome.q,
            choice=greedy_choice(mdp, outcome.q, tie_tolerance=0.0),
            returns=outcome.round_returns,
            episodes=outcome.episodes,
            steps=outcome.steps,
            wall_time=time.perf_counter() - start,
            schedule=schedule.name,
            seed=seed,
            rounds=outcome.rounds,
            converged=outcome.converged,
        )
    rng = random.Random(seed)
    if isinstance(schedule, PaperSchedule):
        q, returns, steps = _train_paper(mdp, schedule, rng, progress)
    elif isinstance(schedule, ExploringStartsSchedule):
        q, returns, steps = _train_explore(mdp, schedule, rng, progress)
    else:
        q, returns, steps = _train_full(mdp, schedule, rng, progress)
    q_arr = np.array(q)
    return LearningResult(
        q=q_arr,
        choice=greedy_choice(mdp, q_arr, tie_tolerance=0.0),
        returns=np.array(returns),
        episodes=len(returns),
        steps=steps,
        wall_time=time.perf_counter() - start,
        schedule=schedule.name,
        seed=seed,
    )


def _episode(
    mdp: SequenceMDP,
    sim: _Simulator,
    q: list[float],
    state: int,
    first_edge: int | None,
    epsilon: float,
    alpha: Callable[[int], float],
    max_steps: int,
) -> tuple[float, int]:
    gamma = mdp.config.gamma
    edge_start = sim.edge_start
    rng = sim.rng
    total, discount, steps = 0.0, 1.0, 0
    while steps < max_steps:
        lo, hi = edge_start[state], edge_start[state + 1]
        if hi == lo:
            break  # terminal: the episode ends
        if first_edge is not None:
            edge, first_edge = first_edge, None
        elif rng.random() < epsilon:
            edge = lo + rng.randrange(hi - lo)
        else:
            edge = _greedy_edge(q, lo, hi, rng)
        nxt, reward = sim.step(state, edge)
        nlo, nhi = edge_start[nxt], edge_start[nxt + 1]
        target = reward + (gamma * max(q[nlo:nhi]) if nhi > nlo else 0.0)
        q[edge] += alpha(edge) * (target - q[edge])
        total += discount * reward
        discount *= gamma
        state = nxt
        steps += 1
    return total, steps


def _train_paper(mdp, schedule: PaperSchedule, rng, progress):
    sim = _Simulator(mdp, rng)
    q = [0.0] * mdp.n_edges
    returns: list[float] = []
    epsilon, steps = schedule.epsilon0, 0
    w = schedule.window
    for episode in range(1, schedule.max_episodes + 1):
        ret, n = _episode(
            mdp, sim, q, 0, None, epsilon, lambda _e: schedule.alpha, schedule.max_steps
        )
        returns.append(ret)
        steps += n
        epsilon = max(schedule.epsilon_min, epsilon - schedule.epsilon_decay)
        if progress:
            progress(episode, 0, ret)
        if epsilon <= schedule.epsilon_min and len(returns) >= 2 * w:
            recent = sum(returns[-w:]) / w
            before = sum(returns[-2 * w : -w]) / w
            if abs(recent - before) < schedule.stop_tolerance:
                break
    return q, returns, steps


def _train_full(mdp, schedule: FullSchedule, rng, progress):
    sim = _Simulator(mdp, rng)
    q = [0.0] * mdp.n_edges
    visits = [0] * mdp.n_edges

    def alpha(edge: int) -> float:
        visits[edge] += 1
        return 1.0 / visits[edge] ** schedule.alpha_power

    pairs = [(int(mdp.edge_src[e]), e) for e in range(mdp.n_edges)]
    returns: list[float] = []
    steps = 0
    previous = None
    for sweep in range(1, schedule.max_sweeps + 1):
        rng.shuffle(pairs)
        for state, edge in pairs:
            ret, n = _episode(mdp, sim, q, state, edge, schedule.epsilon, alpha, schedule.max_steps)
            returns.append(ret)
            steps += n
        if progress:
            progress(sweep, schedule.max_sweeps, returns[-1])
        values = state_values(mdp, np.array(q))
        settled = previous is not None and sweep >= schedule.min_sweeps
        if settled and float(np.max(np.abs(values - previous))) < schedule.stop_tolerance:
            break
        previous = values
    return q, returns, steps


def _train_explore(mdp, schedule: ExploringStartsSchedule, rng, progress):
    sim = _Simulator(mdp, rng)
    q0 = max(0.0, float(mdp.out_reward.max())) if schedule.optimistic and mdp.n_edges else 0.0
    q = [q0] * mdp.n_edges
    visits = [0] * mdp.n_edges

    def alpha(edge: int) -> float:
        visits[edge] += 1
        return 1.0 / visits[edge] ** schedule.alpha_power

    space = mdp.space
    edge_start = sim.edge_start
    starts = [s for s in range(space.n_states) if edge_start[s + 1] > edge_start[s]]
    depth = space.depth.tolist()
    returns: list[float] = []
    steps, stable, previous = 0, 0, None
    for sweep in range(1, schedule.max_sweeps + 1):
        rng.shuffle(starts)
        starts.sort(key=lambda s: -depth[s])  # stable: random order within a depth
        epsilon = schedule.epsilon0 / sweep
        for state in starts:
            lo, hi = edge_start[state], edge_start[state + 1]
            fewest = min(visits[lo:hi])
            least = [e for e in range(lo, hi) if visits[e] == fewest]
            first = least[0] if len(least) == 1 else rng.choice(least)
            ret, n = _episode(mdp, sim, q, state, first, epsilon, alpha, schedule.max_steps)
            returns.append(ret)
            steps += n
        if progress:
            progress(sweep, schedule.max_sweeps, returns[-1])
        choice = greedy_choice(mdp, np.array(q), tie_tolerance=0.0)
        stable = stable + 1 if previous is not None and np.array_equal(choice, previous) else 0
        previous = choice
        if sweep >= schedule.min_sweeps and stable >= schedule.patience:
            break
    return q, returns, steps
