"""Q-learning that covers every state: the default training schedule, vectorised over episodes.

The paper's agent learns from episodes that start at the empty base; on a larger assembly most
states are then seldom or never visited, and its greedy policy is wrong or loops there. This
learner keeps the paper's method — tabular Q-learning from sampled episodes, the MDP's rewards,
no model — and changes where episodes start and when learning stops:

- **Rounds of exploring starts.** A round starts one episode from every (state, task) pair of
  the states it aims at, level by level (deepest states first in odd rounds, shallowest first
  in even ones: values flow up the levels through placements and down them through undos),
  each continued greedily for `continuation` tasks; then one greedy episode ("walk") from every
  aimed state. All episodes of a level advance together as numpy arrays.
- **Aimed where learning is not done.** The next round aims at the states
  - on a loop: a walk that went 2 x depth + 2 proposals in a row, each done as proposed,
    without reaching a terminal state (more than the undos back to the base and a whole
    assembly), or, at a full sweep, from which the greedy policy never finishes;
  - whose greedy task changed by more than the tolerance;
  - with a task whose last update moved its value by more than the tolerance, or whose
    successor, the last time the task was done as proposed, has moved in value since (the
    temporal-difference error that experience would have now: prioritised by error);
  - whose choice is still unresolved (below).
- **Choices within noise are raced.** Each pair keeps the running mean of its squared errors
  (at its own step size): its noise, the operator's mistakes and overrides. Where a task is
  within `confidence` standard errors of its state's greedy task while those errors are still
  larger than `indifference` (two tasks closer than that are equally good), both are sampled
  again within the round, pass after pass, until the choice is resolved (`max_passes`).
- **Step sizes** follow Kesten's rule per (state, task): 1 / (1 + k), where k counts the
  updates whose error was small or changed sign (noise around the estimate); k is reset to 0
  when the value the pair learned from has moved, so that a stale estimate is replaced at once
  while a noisy one averages its samples.
- **Stop rule: coverage.** When a round finds no loop and leaves no choice unresolved, the
  next round is a full sweep: every pair of every non-terminal state, a sampled walk from
  every non-terminal state, and the greedy policy followed as proposed from every state (what
  an episode in which the operator does each proposal shows: the tasks it takes to finish).
  Learning ends at a full sweep that leaves no choice unresolved, after `patience` full sweeps
  in a row found every state finishing, and finishing in the same number of tasks as at the
  sweep before (a change between equally short routes is no change). `max_rounds` caps it
  (the result then says it did not converge).

The learner reads only what an agent observes: the feasible tasks of the state it is in (and
its depth, the number of tasks done), what a task does when done as proposed (the sequence with
the task added; undo: without its last task), and for each task it proposes the reward, the
next state and whether the operator did what it proposed. The environment samples the
operator's overrides and mistakes; the learner never reads their probabilities, the exact
solution or the fewest tasks to finish. The tolerance is in units of the mean |reward| of its
first batch of experience, so the same schedule serves the paper's rewards and seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hrc_drake.tasks.mdp import SequenceMDP
from hrc_drake.tasks.policy_check import follow

Progress = Callable[[int, int, float], None]  # (round, total or 0, mean return of the round)


@dataclass(frozen=True)
class CoverageSchedule:
    """Exploring starts aimed where learning is not done; stops on coverage (module doc)."""

    continuation: int = 3
    tolerance: float = 0.1  # a value change that matters, in mean |reward| of the first batch
    indifference: float = 0.5  # tasks closer than this in value are equally good (same unit)
    confidence: float = 2.5  # standard errors between two tasks before the choice is resolved
    max_passes: int = 16  # passes over unresolved choices per round
    patience: int = 2
    max_rounds: int = 400
    max_steps: int = 100
    name: str = "cover"


@dataclass(frozen=True, eq=False)
class CoverageOutcome:
    """What `train_coverage` learned and how it got there."""

    q: np.ndarray
    round_returns: np.ndarray  # mean return of each round's episodes
    episodes: int
    steps: int
    rounds: int
    full_sweeps: int
    converged: bool  # the stop rule held (else: `max_rounds` was reached)


class _Environment:
    """Samples the MDP: the operator's overrides, then the outcome (mistakes) of the task done."""

    def __init__(self, mdp: SequenceMDP, rng: np.random.Generator):
        self.rng = rng
        self.edge_start = mdp.edge_start
        self.count = np.diff(mdp.edge_start)
        self.out_start = mdp.out_start
        per_edge = np.diff(mdp.out_start)
        cum = np.cumsum(mdp.out_prob)
        before = np.concatenate(([0.0], cum))[mdp.out_start[:-1]]
        self.out_cum = (cum - np.repeat(before, per_edge)).astype(np.float32)
        self.out_dst = mdp.out_dst
        self.edge_dst = mdp.edge_dst
        self.out_reward = mdp.out_reward
        self.most_outcomes = int(per_edge.max()) if len(per_edge) else 1
        self.override = mdp.config.override_prob

    def step(self, states: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, ...]:
        """The next states and rewards of proposing `edges` in `states`, and whether the
        operator did what was proposed (what the interface shows an agent)."""
        rng = self.rng
        performed = edges
        if self.override > 0:
            count = self.count[states]
            other = (count > 1) & (rng.random(len(states)) < self.override)
            if other.any():
                lo = self.edge_start[states[other]]
                pick = lo + (rng.random(int(other.sum())) * (count[other] - 1)).astype(np.int64)
                performed = edges.copy()
                performed[other] = pick + (pick >= edges[other])
        outcome = self.out_start[performed]
        if self.most_outcomes > 1:
            last = self.out_start[performed + 1] - 1
            u = rng.random(len(performed))
            for _ in range(self.most_outcomes - 1):
                outcome += (outcome < last) & (u >= self.out_cum[outcome])
        nxt = self.out_dst[outcome]
        return nxt, self.out_reward[outcome], nxt == self.edge_dst[edges]


SATURATED = np.iinfo(np.uint16).max


class _Learner:
    """The Q-table with its per-pair statistics and the greedy task and value of every state."""

    def __init__(
        self, mdp: SequenceMDP, rng: np.random.Generator, q0: float, relative_tolerance: float
    ):
        n_edges = mdp.n_edges
        self.env = _Environment(mdp, rng)
        self.gamma = mdp.config.gamma
        self.edge_start = mdp.edge_start
        self.count = self.env.count
        self.q = np.full(n_edges, q0)
        self.settled = np.zeros(n_edges, np.uint16)  # Kesten's k (saturates: steps >= 1.5e-5)
        self.sign = np.zeros(n_edges, np.int8)  # sign of the last large error
        # Running mean of each pair's squared errors, at its own step size: its noise (the
        # operator's mistakes and overrides) and how stale it is.
        self.spread = np.zeros(n_edges, np.float32)
        self.edge_src = mdp.edge_src
        self.last_change = np.zeros(n_edges, np.float32)
        # The next state of the last time each task was done as proposed, and its value then
        # (NaN: not yet): how the staleness of a task's estimate is judged.
        self.last_next = np.zeros(n_edges, np.int32)
        self.value_used = np.full(n_edges, np.nan, np.float32)
        self.value = np.where(self.count > 0, q0, 0.0)
        self.best = np.where(self.count > 0, self.edge_start[:-1], -1).astype(np.int32)
        self.relative_tolerance = relative_tolerance
        self.tolerance = 0.0  # set by the first batch of experience (the reward scale)
        self.steps = 0
        self.episodes = 0

    def refresh(self, states: np.ndarray) -> None:
        """Greedy task (first of the best, in canonical order) and value of `states`."""
        count = self.count[states]
        offsets = np.cumsum(count) - count
        within = np.arange(int(count.sum())) - np.repeat(offsets, count)
        edges = np.repeat(self.edge_start[states], count) + within
        values = self.q[edges]
        best_value = np.maximum.reduceat(values, offsets)
        first = np.where(values >= np.repeat(best_value, count), within, np.iinfo(np.int64).max)
        self.best[states] = self.edge_start[states] + np.minimum.reduceat(first, offsets)
        self.value[states] = best_value

    def update(self, states, edges, nxt, reward, followed) -> None:
        """One Q-learning update per (state, task, reward, next state) of the batch;
        `followed`: whether the operator did the task as proposed."""
        if not self.tolerance:
            # The reward scale: the mean |reward| of the first batch of experience.
            scale = float(np.mean(np.abs(reward))) or 1.0
            self.tolerance = self.relative_tolerance * scale
        value_next = self.value[nxt]
        q_old = self.q[edges]
        error = reward + self.gamma * value_next - q_old
        large = np.abs(error) >= self.tolerance
        sign = (large & (error > 0)).astype(np.int8) - (large & (error < 0))
        previous = self.sign[edges]  # of the last large error
        flipped = large & (previous != 0) & (sign != previous)
        settled = np.minimum(self.settled[edges] + (~large | flipped), SATURATED)
        self.settled[edges] = settled
        self.sign[edges] = np.where(large, sign, previous)
        step = 1.0 / (1.0 + settled)
        q_new = q_old + error * step
        self.q[edges] = q_new
        spread = self.spread[edges]
        self.spread[edges] = spread + (error * error - spread) * step
        self.last_change[edges] = np.abs(q_new - q_old)
        self.last_next[edges[followed]] = nxt[followed]
        self.value_used[edges[followed]] = value_next[followed]
        self._follow(states, edges, q_new)

    def _follow(self, states: np.ndarray, edges: np.ndarray, new: np.ndarray) -> None:
        """Keep each state's greedy task and value after its `edges` were updated: a task that
        now beats the greedy one takes its place; a greedy task whose value fell, or a batch
        that updated one state twice, has the state's tasks compared again (`refresh`)."""
        best = self.best[states]
        value = self.value[states]
        fell = (edges == best) & (new < value)
        rose = (edges == best) & ~fell
        self.value[states[rose]] = new[rose]
        beats = (edges != best) & ((new > value) | ((new == value) & (edges < best)))
        self.best[states[beats]] = edges[beats]
        self.value[states[beats]] = new[beats]
        best = self.best[states]
        top = self.q[best]
        wrong = (top < new) | ((top == new) & (edges < best)) | (self.value[states] != top)
        again = states[fell | wrong]
        if len(again):
            # Exploring starts update all tasks of a state at once: drop adjacent repeats.
            keep = np.ones(len(again), bool)
            keep[1:] = again[1:] != again[:-1]
            self.refresh(again[keep])

    def episodes_from(self, states, first, steps, loop_after=0):
        """Episodes from `states`, opened with `first` (greedy where None), for up to `steps`
        tasks or until a terminal state. With `loop_after`, an episode that goes that many
        proposals in a row, each done as proposed, without reaching a terminal state is going
        round in circles: it is stopped there. Returns whether each episode reached a terminal
        state, their returns, and the last three states of those stopped as loops."""
        self.episodes += len(states)
        ids = np.arange(len(states))
        reached = np.zeros(len(states), bool)
        returns = np.zeros(len(states))
        streak = np.zeros(len(states), np.int32)
        before = np.stack([states, states])  # the two states before the current one
        loops = []
        discount = 1.0
        edges = first
        for _ in range(steps):
            if edges is None:
                edges = self.best[states]
            nxt, reward, followed = self.env.step(states, edges)
            self.update(states, edges, nxt, reward, followed)
            returns[ids] += discount * reward
            discount *= self.gamma
            self.steps += len(states)
            going = self.count[nxt] > 0
            reached[ids[~going]] = True
            if loop_after:
                streak = np.where(followed, streak + 1, 0)
                circling = going & (streak >= loop_after)
                if circling.any():
                    last3 = (nxt[circling], states[circling], before[0][circling])
                    loops.append(np.concatenate(last3))
                    going &= ~circling
                before = np.stack([states, before[0]])[:, going]
                streak = streak[going]
            states, ids, edges = nxt[going], ids[going], None
            if not len(states):
                break
        loop_states = np.concatenate(loops) if loops else np.zeros(0, np.int32)
        return reached, returns, loop_states

    def unresolved(self, indifference: float, confidence: float) -> np.ndarray:
        """Pairs whose state's choice is not settled: a task within `confidence` standard
        errors of the greedy one, while those errors are still larger than `indifference` (two
        tasks that close are equally good); and the greedy tasks they contest."""
        hot = []
        for lo in range(0, len(self.q), 8 * BATCH):  # in blocks: no full-size temporaries
            edges = np.arange(lo, min(lo + 8 * BATCH, len(self.q)))
            greedy = self.best[self.edge_src[edges]]
            variance = self.spread[edges] / (np.float32(1.0) + self.settled[edges])
            own = self.spread[greedy] / (np.float32(1.0) + self.settled[greedy])
            width = confidence * np.sqrt(own + variance)
            close = (self.q[greedy] - self.q[edges] < width) & (width >= indifference)
            close &= greedy != edges  # a greedy task does not contest itself
            hot += [edges[close], greedy[close]]
        return np.unique(np.concatenate(hot)) if hot else np.zeros(0, np.int64)

    def stale(self) -> np.ndarray:
        """Pairs whose successor (the last time they were done as proposed) has moved in value
        since they learned from it; their step size starts again (Kesten's k = 0)."""
        moved = self.gamma * np.abs(self.value[self.last_next] - self.value_used)
        stale = moved >= self.tolerance  # False where not yet done as proposed (NaN)
        self.settled[stale] = 0
        self.sign[stale] = 0
        return stale


# Episodes stepped together: large enough that numpy's per-call overhead is small, small enough
# that the batch's temporaries fit in what building the MDP freed (measured: at 95,306 and
# 820,427 states the learner then adds nothing to the peak of states and MDP; 2^17 added 8 MB
# at 95,306 states for 10 % less time; benchmarks/reports/coverage.md).
BATCH = 1 << 15


def _followed(space, learner: _Learner) -> np.ndarray:
    """Tasks to a terminal state from every state, following the greedy policy as proposed
    (what an episode in which the operator does each proposal shows; -1: never)."""
    nxt = np.where(learner.best >= 0, learner.env.edge_dst[np.maximum(learner.best, 0)], -1)
    return follow(space, nxt).steps


def _batches(states: np.ndarray, weight: np.ndarray | None = None):
    """`states` in consecutive runs of at most BATCH episodes (a state weighs `weight[state]`
    episodes: one per task for exploring starts; one for walks)."""
    if weight is None:
        for lo in range(0, len(states), BATCH):
            yield states[lo : lo + BATCH]
        return
    ends = np.cumsum(weight[states])
    cuts = np.searchsorted(ends, np.arange(BATCH, int(ends[-1]) if len(ends) else 0, BATCH))
    yield from (part for part in np.split(states, cuts) if len(part))


def _exploring_starts(
    learner: _Learner, depth: np.ndarray, aimed: np.ndarray, deepest_first: bool, steps: int
) -> float:
    """One episode from each task of each aimed state, level by level (deepest or shallowest
    first); the sum of their returns."""
    total, levels = 0.0, depth[aimed]
    for level in sorted(set(levels.tolist()), reverse=deepest_first):
        for states in _batches(aimed[levels == level], learner.count):
            count = learner.count[states]
            offsets = np.cumsum(count) - count
            first = np.repeat(learner.edge_start[states] - offsets, count)
            pairs = first + np.arange(int(count.sum()))
            _, returns, _ = learner.episodes_from(np.repeat(states, count), pairs, steps)
            total += float(returns.sum())
    return total


def _greedy_walks(learner: _Learner, aimed: np.ndarray, steps: int, loop_after: int):
    """One greedy walk from each aimed state; (the sum of their returns, the states whose walk
    went round in circles)."""
    total, late = 0.0, []
    for states in _batches(aimed):
        _, returns, circling = learner.episodes_from(states, None, steps, loop_after)
        total += float(returns.sum())
        late.append(circling)
    return total, np.concatenate(late)


def _race(learner: _Learner, edge_src: np.ndarray, schedule: CoverageSchedule):
    """Choices within noise of each other, sampled again until resolved (racing the
    contenders), one episode per pair and pass (a batch updates a pair once); (the sum of the
    returns, the states still unresolved)."""
    indifference = schedule.indifference * learner.tolerance / schedule.tolerance
    total = 0.0
    for _ in range(schedule.max_passes):
        hot = learner.unresolved(indifference, schedule.confidence)
        if not len(hot):
            break
        for lo in range(0, len(hot), BATCH):
            pairs = hot[lo : lo + BATCH]
            _, returns, _ = learner.episodes_from(edge_src[pairs], pairs, schedule.continuation)
            total += float(returns.sum())
    return total, np.unique(edge_src[learner.unresolved(indifference, schedule.confidence)])


def _aim(learner: _Learner, edge_src: np.ndarray, *where: np.ndarray) -> np.ndarray:
    """The non-terminal states among `where` (index arrays), and those whose values still move
    or have gone stale: the next round's exploring starts."""
    aim = np.zeros(len(learner.count), bool)
    for states in where:
        aim[states] = True
    aim[edge_src[learner.last_change >= learner.tolerance]] = True
    aim[edge_src[learner.stale()]] = True
    return np.flatnonzero(aim & (learner.count > 0)).astype(np.int32)


def train_coverage(
    mdp: SequenceMDP,
    schedule: CoverageSchedule,
    seed: int = 0,
    progress: Progress | None = None,
) -> CoverageOutcome:
    """Learn a Q-table for `mdp` with `schedule` (module doc); seeded: same seed, same table."""
    space = mdp.space
    q0 = max(0.0, float(mdp.out_reward.max())) if mdp.n_edges else 0.0  # optimistic start
    learner = _Learner(mdp, np.random.default_rng(seed), q0, schedule.tolerance)
    non_terminal = np.flatnonzero(learner.count > 0).astype(np.int32)
    # Followed as proposed, a greedy walk needs at most the undos back to the base and the
    # tasks of a whole assembly; a longer run of followed proposals is going round in circles.
    loop_after = 2 * int(space.depth.max()) + 2
    aimed, full, previous = non_terminal, True, learner.best[non_terminal].copy()
    round_returns: list[float] = []
    routes, stable, full_sweeps, rounds, converged = None, 0, 0, 0, False
    for rounds in range(1, schedule.max_rounds + 1):
        episodes_before = learner.episodes
        total = _exploring_starts(
            learner, space.depth, aimed, rounds % 2 == 1, schedule.continuation
        )
        walked, late = _greedy_walks(learner, aimed, schedule.max_steps, loop_after)
        raced, unresolved = _race(learner, mdp.edge_src, schedule)
        round_returns.append((total + walked + raced) / max(learner.episodes - episodes_before, 1))
        choice = learner.best[non_terminal]
        gain = learner.value[non_terminal] - learner.q[previous]
        changed = (choice != previous) & (gain >= learner.tolerance)
        unfinished = np.zeros(0, np.int32)
        if full:
            full_sweeps += 1
            # The greedy policy followed as proposed, from every state: the tasks it takes to
            # finish (-1: never). The same as at the last full sweep, and finishing everywhere,
            # is one more stable sweep; a change between equally short routes is no change.
            now = _followed(space, learner)
            unfinished = non_terminal[now[non_terminal] < 0]
            same = routes is not None and np.array_equal(now, routes)
            stable = stable + 1 if same and len(unfinished) == 0 else 0
            routes = now
        if progress:
            progress(rounds, 0, round_returns[-1])
        if full and stable >= schedule.patience and len(unresolved) == 0:
            converged = True  # the policy is the one this full sweep checked
            break
        aimed = _aim(learner, mdp.edge_src, late, unfinished, unresolved, non_terminal[changed])
        full = len(aimed) == 0 or (len(late) == 0 and len(unresolved) == 0 and not full)
        if full:
            aimed = non_terminal
        previous = choice
    return CoverageOutcome(
        q=learner.q,
        round_returns=np.array(round_returns),
        episodes=learner.episodes,
        steps=learner.steps,
        rounds=rounds,
        full_sweeps=full_sweeps,
        converged=converged,
    )
