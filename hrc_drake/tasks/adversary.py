"""Learning against an adversary: the operator as an opponent with a budget of mistakes.

**The game.** An augmented state is (s, k): the task sequence s and the k mistakes the operator
has left, k = 0 .. K. The robot proposes a feasible task of s; the operator answers after seeing
it: it follows, or — while k > 0 and the proposal is a placement named in the spec's
``mistakes`` — performs one of the proposal's mistake alternatives (another seat of the same
part and mount: the outcomes of `build_mdp` with a mistake probability above 0). Overrides are
excluded: an operator who may override forever never lets a run finish, and every worst case
would be infinite. This is the game of the ``worst-case`` decider (`WorstCaseDecider`), in tasks.

**The budget and undo.** A misplacement uses one mistake; undoing the misplaced part gives none
back, and an undo is never a mistake (it has no alternative to perform). So k only falls, after
K misplacements the operator follows, and every worst case is finite: the robot can always undo
back to a state from which following finishes.

**The payoff.** The paper's reward: -1 per task, +2 for the task that reaches a terminal state,
discounted by the `MdpConfig`'s gamma. A run of T tasks returns
f(T) = -(1 + g + ... + g^(T-2)) + 2 g^(T-1), strictly decreasing in T (f(T+1) - f(T) =
g^(T-1) (2g - 3) < 0 for g <= 1), so the robot maximising the return against an operator who
minimises it plays the same strategies as the robot minimising tasks against an operator who
maximises them, and the game value is f(worst-case tasks).

**Pure strategies.** The operator answers after seeing the proposal: moves alternate, the game
has perfect information, and both sides have optimal pure strategies. The value of (s, k) is
max over proposals of min over answers — Littman's (1994) minimax-Q without its linear
program, which only a game of simultaneous moves (mixed strategies) needs.

Here:

- `adversary_game`: the game's flat arrays; `worst_case_q` / `worst_case_levels`: the min-max
  backup and its value iteration, level by level (k = 0 first: a level reads the one below),
  shared with `WorstCaseDecider` (which prices answers in seconds and bets).
- `solve_minimax`: exact worst-case tasks to finish, game values and min-max proposals for every
  (s, k), k = 0..K.
- `policy_worst_case`: the exact best response to a fixed policy — its worst-case tasks from
  every (s, k), or -1 where the operator can keep it from finishing (it loops).
- `train_minimax`: the model-free learner (minimax-Q over (s, k, proposal, answer)), trained
  against `CyclingOpponent`, with exploring starts and a coverage-and-stability stop rule.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.mdp import UNDO_INDEX, MdpConfig, SequenceMDP, build_mdp
from hrc_drake.tasks.policy import Policy, policy_from_choices
from hrc_drake.tasks.solve import greedy_choice

Progress = Callable[[int, int, float], None]  # (round, max rounds, values changed)
NEVER = -1  # worst-case tasks of a policy the operator can keep from finishing


@dataclass(frozen=True, eq=False)
class AdversaryGame:
    """The augmented game's arrays: the MDP's edges (proposals) and outcomes (answers).

    `deviates[o]`: outcome o is a misplacement (uses a mistake); `performed[o]`: the edge, in the
    proposal's state, of the task the operator performed (the proposal's own edge when it
    follows).
    """

    mdp: SequenceMDP
    budget: int
    deviates: np.ndarray
    performed: np.ndarray

    @property
    def space(self) -> StateSpace:
        """The state space."""
        return self.mdp.space

    @property
    def gamma(self) -> float:
        """The discount of the paper's reward."""
        return self.mdp.config.gamma

    def terminal(self) -> np.ndarray:
        """Per state: whether a run ends there."""
        return self.space.kind == StateKind.TERMINAL


def adversary_game(
    space: StateSpace, budget: int, config: MdpConfig | None = None
) -> AdversaryGame:
    """The game of `space` with a budget of `budget` mistakes, the paper's reward and the gamma of
    `config` (default `MdpConfig()`; its mistake and override probabilities play no part: the
    operator's answers are chosen, not drawn). ValueError for a negative budget or task costs."""
    config = config or MdpConfig()
    if budget < 0:
        raise ValueError(f"a budget of mistakes is a whole number >= 0, got {budget}")
    if config.rewards.task_costs is not None or config.rewards.edge_costs is not None:
        raise ValueError("the adversarial game uses the paper's reward: give no task costs")
    # Any mistake probability above 0 gives each placement its whole set of outcomes.
    mdp = build_mdp(space, replace(config, mistake_prob=0.5, override_prob=0.0))
    out_edge = np.repeat(np.arange(mdp.n_edges), np.diff(mdp.out_start))
    deviates = mdp.out_dst != mdp.edge_dst[out_edge]
    into = np.full(space.n_states, -1, dtype=np.int64)  # the placement edge into each state
    placements = np.flatnonzero(mdp.edge_task != UNDO_INDEX)
    into[mdp.edge_dst[placements]] = placements
    performed = np.where(deviates, into[mdp.out_dst], out_edge)
    return AdversaryGame(mdp=mdp, budget=int(budget), deviates=deviates, performed=performed)


def worst_case_q(
    mdp: SequenceMDP,
    out_costs: Sequence[np.ndarray],
    deviates: np.ndarray,
    w: np.ndarray,
    below: np.ndarray | None,
    gamma: float = 1.0,
) -> np.ndarray:
    """Per edge, the cost of proposing it against the worst answer: for each pricing of the
    outcomes in `out_costs` (the decider's bets; one array for tasks), the largest cost plus
    `gamma` times the next state's value — from `w` (the same mistakes left) when following,
    from `below` (one fewer) when misplacing — and the cheapest pricing. `below` None: no
    mistake left, the operator follows."""
    if mdp.n_edges == 0:
        return np.zeros(0)
    nxt = gamma * w[mdp.out_dst]
    if below is not None:
        nxt = np.where(deviates, gamma * below[mdp.out_dst], nxt)
    q = np.full(mdp.n_edges, np.inf)
    for cost in out_costs:
        val = cost + nxt
        if below is None:
            val = np.where(deviates, -np.inf, val)
        q = np.minimum(q, np.maximum.reduceat(val, mdp.out_start[:-1]))
    return q


def worst_case_levels(
    mdp: SequenceMDP,
    out_costs: Sequence[np.ndarray],
    deviates: np.ndarray,
    budget: int,
    gamma: float = 1.0,
) -> list[np.ndarray]:
    """Min-max values (cost to finish) of every state with 0, 1, .., `budget` mistakes left.

    Value iteration per level, from the level below (a lower bound: more mistakes never make a
    state cheaper) or zeros, to the exact fixed point: a sweep is a min-max backup of every edge
    (`worst_case_q`) and a minimum per state. Converges in about as many sweeps as the longest
    worst case has tasks; RuntimeError if a level does not settle (a state that cannot finish).
    """
    n = mdp.space.n_states
    has = np.diff(mdp.edge_start) > 0
    seg = mdp.edge_start[:-1][has]
    levels: list[np.ndarray] = []
    below = None
    for k in range(budget + 1):
        w = np.zeros(n) if below is None else below.copy()
        for _sweep in range(10 * n + 10):
            new = np.zeros(n)
            if len(seg):
                new[has] = np.minimum.reduceat(
                    worst_case_q(mdp, out_costs, deviates, w, below, gamma), seg
                )
            if np.array_equal(new, w):
                break
            w = new
        else:
            raise RuntimeError(
                f"the min-max values with {k} mistake(s) left did not settle in {10 * n + 10} "
                "sweeps: some state cannot reach a terminal state; check the spec"
            )
        levels.append(w)
        below = w
    return levels


@dataclass(frozen=True, eq=False)
class MinimaxSolution:
    """The exact solution of the game: per (mistakes left k, state s), arrays of shape (K+1, n).

    `tasks`: worst-case tasks to finish (undo counted; 0 in terminal states); `values`: the game
    value under the paper's reward (= f(tasks), see the module doc); `choice`: the min-max
    proposal (an edge; the first in the spec's task order among equals; -1 in terminal states).
    """

    game: AdversaryGame
    tasks: np.ndarray
    values: np.ndarray
    choice: np.ndarray
    wall_time: float


def solve_minimax(game: AdversaryGame) -> MinimaxSolution:
    """Exact min-max of `game` in tasks and in the paper's reward, for k = 0 .. budget."""
    start = time.perf_counter()
    mdp = game.mdp
    ones = np.ones(len(mdp.out_dst))
    tasks = worst_case_levels(mdp, [ones], game.deviates, game.budget)
    costs = worst_case_levels(mdp, [-mdp.out_reward], game.deviates, game.budget, game.gamma)
    choice = np.full((game.budget + 1, game.space.n_states), -1, dtype=np.int64)
    for k, w in enumerate(tasks):
        below = tasks[k - 1] if k > 0 else None
        q = worst_case_q(mdp, [ones], game.deviates, w, below)
        choice[k] = greedy_choice(mdp, -q, tie_tolerance=0.0)
    return MinimaxSolution(
        game=game,
        tasks=np.rint(np.array(tasks)).astype(np.int64),
        values=-np.array(costs),
        choice=choice,
        wall_time=time.perf_counter() - start,
    )


def paper_return(tasks: np.ndarray, gamma: float) -> np.ndarray:
    """f(T): the discounted return of a run of T tasks under the paper's reward (0 for T = 0)."""
    t = np.maximum(np.asarray(tasks, dtype=float) - 1, 0)  # tasks before the last
    paid = t if gamma == 1.0 else (1 - gamma**t) / (1 - gamma)
    return np.where(np.asarray(tasks) > 0, -paid + 2 * gamma**t, 0.0)


def policy_worst_case(game: AdversaryGame, choice: np.ndarray) -> np.ndarray:
    """Worst-case tasks to finish of a fixed policy from every (k, s), shape (K+1, n): the
    operator's exact best response (its longest run against the policy), `NEVER` (-1) where it
    can keep the policy from ever finishing (the policy loops).

    `choice` is an edge per state, (n,) (the same at every k: a policy file) or (K+1, n); -1 in
    terminal states. The best response is a longest path on the policy's graph of augmented
    states, found by peeling (Kahn's order backwards from the terminal states): a node is
    settled once all its successors are, so nodes left unsettled reach a cycle.
    """
    mdp, n, levels = game.mdp, game.space.n_states, game.budget + 1
    choice = np.broadcast_to(np.asarray(choice, dtype=np.int64), (levels, n))
    terminal = np.tile(game.terminal(), levels)
    k_of = np.repeat(np.arange(levels), n)
    node = np.flatnonzero(~terminal)
    if np.any(choice.reshape(-1)[node] < 0):
        raise ValueError("the policy has no proposal in some non-terminal state")
    edge = choice.reshape(-1)[node]
    count = np.diff(mdp.out_start)[edge]
    arc_src = np.repeat(node, count)
    out = np.repeat(mdp.out_start[edge], count) + (
        np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    )
    k = k_of[arc_src]
    legal = ~game.deviates[out] | (k > 0)
    arc_src, out, k = arc_src[legal], out[legal], k[legal]
    arc_dst = (k - game.deviates[out]) * n + mdp.out_dst[out]

    size = levels * n
    value = np.zeros(size, dtype=np.int64)
    settled = terminal.copy()
    pending = np.bincount(arc_src, minlength=size) - np.bincount(
        arc_src[settled[arc_dst]], minlength=size
    )
    while True:
        ready = ~settled & (pending == 0)
        if not ready.any():
            break
        arcs = ready[arc_src]
        np.maximum.at(value, arc_src[arcs], 1 + value[arc_dst[arcs]])
        settled |= ready
        pending -= np.bincount(arc_src[ready[arc_dst]], minlength=size)
    value[~settled] = NEVER
    return value.reshape(levels, n)


@dataclass(frozen=True)
class Agreement:
    """How a policy's worst case compares with the exact min-max over the non-terminal (s, k).

    `per_level[k]`: states with k mistakes left where they are equal (of `states_per_level`);
    `loops`: augmented states from which the operator can keep the policy from finishing;
    `first_difference`: (k, state) of the first that differs, or None.
    """

    states: int
    equal: int
    per_level: tuple[int, ...]
    states_per_level: int
    loops: int
    longer: int
    first_difference: tuple[int, int] | None

    @property
    def all_equal(self) -> bool:
        """Whether the worst case is the min-max one from every non-terminal (s, k)."""
        return self.equal == self.states


def agreement(solution: MinimaxSolution, worst: np.ndarray) -> Agreement:
    """Compare `worst` (`policy_worst_case`) with the exact min-max tasks of `solution`."""
    live = ~solution.game.terminal()
    same = (worst == solution.tasks) & live
    differ = np.argwhere(~same & live)
    return Agreement(
        states=int(live.sum()) * worst.shape[0],
        equal=int(same.sum()),
        per_level=tuple(int(x) for x in same.sum(axis=1)),
        states_per_level=int(live.sum()),
        loops=int(((worst == NEVER) & live).sum()),
        longer=int(((worst > solution.tasks) & live).sum()),
        first_difference=None if len(differ) == 0 else (int(differ[0][0]), int(differ[0][1])),
    )


class CyclingOpponent:
    """The training opponent (the learner's environment): to each proposal it answers with each
    of its answers in turn — following, or a mistake alternative while it has mistakes left —
    from a seeded starting point per (k, proposal). Any run of as many consecutive tries of a
    (k, proposal) as it has answers shows all of them, so the learner sees every answer it must
    guard against without knowing how many there are.
    """

    def __init__(self, game: AdversaryGame, rng: np.random.Generator):
        mdp = game.mdp
        self.game = game
        self.n_edges = mdp.n_edges
        outcomes = np.diff(mdp.out_start)
        levels = game.budget + 1
        # Answers of (k, e): the proposal's outcomes when mistakes are left; else following.
        self.count = np.where(np.arange(levels)[:, None] > 0, outcomes[None, :], 1).reshape(-1)
        self.offset = (rng.random(levels * mdp.n_edges) * self.count).astype(np.int64)
        self.tries = np.zeros(levels * mdp.n_edges, dtype=np.int64)
        out_edge = np.repeat(np.arange(mdp.n_edges), outcomes)
        self.follow = np.empty(mdp.n_edges, dtype=np.int64)
        self.follow[out_edge[~game.deviates]] = np.flatnonzero(~game.deviates)
        self.done = game.terminal()

    def answer(self, k: np.ndarray, edge: np.ndarray):
        """Answer the proposals `edge` made with `k` mistakes left (arrays, one per episode).

        Returns the edge of the task performed, the next state, the mistakes left, the reward
        and whether the run ended. Proposals repeated in one call are answered as consecutive
        tries, in the order given."""
        mdp, game = self.game.mdp, self.game
        key = k * self.n_edges + edge
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        first = np.ones(len(key), dtype=bool)
        first[1:] = sorted_key[1:] != sorted_key[:-1]
        pos = np.arange(len(key))
        rank = np.empty(len(key), dtype=np.int64)
        rank[order] = pos - np.maximum.accumulate(np.where(first, pos, 0))
        i = (self.tries[key] + self.offset[key] + rank) % self.count[key]
        o = np.where(k > 0, mdp.out_start[edge] + i, self.follow[edge])
        np.add.at(self.tries, key, 1)
        nxt = mdp.out_dst[o]
        return game.performed[o], nxt, k - game.deviates[o], mdp.out_reward[o], self.done[nxt]


@dataclass(frozen=True)
class MinimaxSchedule:
    """How `train_minimax` explores and when it stops.

    Every round starts one episode from every (state, mistakes left, proposal) of the
    non-terminal states, deepest states first (their values are what shallower ones bootstrap
    from), with the proposal; the episode goes on greedily (max-min) to a terminal state or
    `max_steps` tasks. It stops after the first round in which (coverage) every proposal of
    every augmented state has been tried `confirm` times more than it has shown distinct
    answers (an answer came back: against `CyclingOpponent` all have been seen), and
    (stability) no value changed, every stored value was recomputed since the last change, and
    every episode reached a terminal state — or after `max_rounds` rounds (not converged).
    Then every stored value is the backup of the values as they stand, over every answer: a
    fixed point of the game's min-max backup, which is unique (every task costs) — the game's
    values, read from episodes alone.
    """

    confirm: int = 1
    max_rounds: int = 200
    max_steps: int = 100


@dataclass(frozen=True, eq=False)
class MinimaxResult:
    """What `train_minimax` learned, and the effort.

    Per (k, s), shape (K+1, n): `values`, max over proposals of min over the answers seen (0 in
    terminal states), and `choice`, the greedy proposal (-1 in terminal states). Its Q, shape
    (K+1, edges, slots): `q[k, e, c]` for the c-th distinct answer seen to proposal e with k
    mistakes left, `answer[k, e, c]` the edge of the task performed then (-1 and NaN: no such
    answer seen)."""

    values: np.ndarray
    choice: np.ndarray
    q: np.ndarray
    answer: np.ndarray
    episodes: int
    steps: int
    rounds: int
    converged: bool
    wall_time: float
    seed: int


def _greedy(
    q_min: np.ndarray, edge_start: np.ndarray, n_edges: int, k: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per (k, s) of a batch of non-terminal states: max over proposals of `q_min` and the first
    proposal (in the spec's task order) that reaches it."""
    degree = edge_start[s + 1] - edge_start[s]
    begin = np.cumsum(degree) - degree
    within = np.arange(int(degree.sum())) - np.repeat(begin, degree)
    edges = np.repeat(edge_start[s], degree) + within
    vals = q_min[np.repeat(k, degree) * n_edges + edges]
    best = np.maximum.reduceat(vals, begin)
    hit = np.flatnonzero(vals == np.repeat(best, degree))
    episode = np.repeat(np.arange(len(s)), degree)[hit]
    first = np.ones(len(hit), dtype=bool)
    first[1:] = episode[1:] != episode[:-1]
    return best, edges[hit[first]]


class _AnswerTable:
    """Minimax-Q's table: per (k, proposal) row, a slot per distinct answer seen (grown as
    answers come), its value, the round of its last backup, and the row's minimum over its
    answers (a proposal never tried: `optimistic`)."""

    def __init__(self, rows: int, n_edges: int, optimistic: float):
        self.n_edges, self.slots = n_edges, 1
        self.q = np.full((rows, 1), np.nan)
        self.answer = np.full((rows, 1), -1, dtype=np.int64)
        self.updated = np.full((rows, 1), -1, dtype=np.int16)  # round of the last backup
        self.seen = np.zeros(rows, dtype=np.int64)  # distinct answers seen
        self.tries = np.zeros(rows, dtype=np.int64)
        self.q_min = np.full(rows, optimistic)

    def slot(self, row: np.ndarray, performed: np.ndarray) -> np.ndarray:
        """The slot of each (row, answer), a new one for an answer not seen before."""
        match = self.answer[row] == performed[:, None]
        new = ~match.any(axis=1)
        if new.any():
            key = np.unique(row[new] * self.n_edges + performed[new])
            r, p = key // self.n_edges, key % self.n_edges
            first = np.ones(len(r), dtype=bool)
            first[1:] = r[1:] != r[:-1]
            pos = np.arange(len(r))
            col = self.seen[r] + pos - np.maximum.accumulate(np.where(first, pos, 0))
            if col.max() >= self.slots:
                self._grow(int(col.max()) + 1 - self.slots)
            self.answer[r, col] = p
            np.add.at(self.seen, r, 1)
            match = self.answer[row] == performed[:, None]
        return np.argmax(match, axis=1)

    def _grow(self, grow: int) -> None:
        rows = len(self.seen)
        self.q = np.hstack([self.q, np.full((rows, grow), np.nan)])
        self.answer = np.hstack([self.answer, np.full((rows, grow), -1, dtype=np.int64)])
        self.updated = np.hstack([self.updated, np.full((rows, grow), -1, dtype=np.int16)])
        self.slots += grow

    def backup(self, row: np.ndarray, col: np.ndarray, target: np.ndarray, rnd: int) -> int:
        """Set the slots to `target` in round `rnd`; how many changed (a new slot counts)."""
        changed = int(np.count_nonzero(~(self.q[row, col] == target)))  # NaN: new
        self.q[row, col] = target
        self.updated[row, col] = rnd
        np.add.at(self.tries, row, 1)
        self.q_min[row] = np.nanmin(self.q[row], axis=1)  # repeated rows: the same value
        return changed

    def settled(self, confirm: int, last_change: int) -> bool:
        """Every answer seen tried `confirm` more times, and every slot backed up since the
        last change."""
        covered = bool(np.all(self.tries >= self.seen + confirm))
        return covered and bool(np.all(self.updated[self.answer >= 0] > last_change))


def _starts_by_depth(game: AdversaryGame) -> list[tuple[np.ndarray, np.ndarray]]:
    """A round's exploring starts: every (k, proposal), one batch per depth, deepest first."""
    space, src, levels = game.space, game.mdp.edge_src, game.budget + 1
    starts = []
    for d in range(int(space.depth.max()), -1, -1):
        e = np.flatnonzero(space.depth[src] == d)
        if len(e):
            starts.append((np.repeat(np.arange(levels), len(e)), np.tile(e, levels)))
    return starts


def _play(game, table: _AnswerTable, opponent, k, e, rnd: int, max_steps: int):
    """A batch of greedy episodes from the proposals `e` with `k` mistakes left, backed up as
    they go; (slots changed, steps, episodes that ran out of steps)."""
    n_edges, edge_start, changed, steps = game.mdp.n_edges, game.mdp.edge_start, 0, 0
    for _step in range(max_steps):
        performed, s2, k2, reward, done = opponent.answer(k, e)
        row = k * n_edges + e
        col = table.slot(row, performed)
        v2, go = np.zeros(len(e)), ~done
        if go.any():
            v2[go] = _greedy(table.q_min, edge_start, n_edges, k2[go], s2[go])[0]
        changed += table.backup(row, col, reward + game.gamma * v2, rnd)
        steps += len(e)
        k = k2[go]
        if not go.any():
            break
        e = _greedy(table.q_min, edge_start, n_edges, k, s2[go])[1]
    return changed, steps, len(k)


def train_minimax(
    game: AdversaryGame,
    schedule: MinimaxSchedule | None = None,
    seed: int = 0,
    progress: Progress | None = None,
) -> MinimaxResult:
    """Minimax-Q against `CyclingOpponent`, seeded (the opponent's order of answers).

    Model-free: it knows each state's feasible tasks and depth (the state is the task
    sequence), and learns from the episodes' observed answers, rewards, next augmented states
    and ends; it never reads the game's outcomes or the exact solution. Its table grows a slot
    per distinct answer seen to a (k, proposal). Backups use a learning rate of 1, right for a
    deterministic game: Q(s, k, a, answer) = r + gamma V(s', k'), with V = max over proposals of
    min over the answers seen, 0 where the run ended; a proposal never tried is worth the
    largest return of the paper's reward (+2: optimistic, so greedy episodes go where nothing
    is known yet). The episodes of a round start in batches, one per depth, stepped together
    with numpy.
    """
    schedule = schedule or MinimaxSchedule()
    start = time.perf_counter()
    opponent = CyclingOpponent(game, np.random.default_rng(seed))
    mdp, levels = game.mdp, game.budget + 1
    n_edges, rewards = mdp.n_edges, mdp.config.rewards
    table = _AnswerTable(levels * n_edges, n_edges, max(rewards.terminal, rewards.step))
    starts_by_depth = _starts_by_depth(game)
    episodes = steps = rnd = 0
    last_change, converged = -1, False
    for rnd in range(1, min(schedule.max_rounds, np.iinfo(np.int16).max) + 1):
        changed = unfinished = 0
        for k, e in starts_by_depth:
            episodes += len(e)
            batch = _play(game, table, opponent, k, e, rnd, schedule.max_steps)
            changed, steps, unfinished = changed + batch[0], steps + batch[1], unfinished + batch[2]
        last_change = rnd if changed else last_change
        if progress:
            progress(rnd, schedule.max_rounds, changed)
        if not changed and not unfinished and table.settled(schedule.confirm, last_change):
            converged = True
            break
    values, choice = _greedy_everywhere(game, table.q_min)
    return MinimaxResult(
        values=values,
        choice=choice,
        q=table.q.reshape(levels, n_edges, table.slots),
        answer=table.answer.reshape(levels, n_edges, table.slots),
        episodes=episodes,
        steps=steps,
        rounds=rnd,
        converged=converged,
        wall_time=time.perf_counter() - start,
        seed=seed,
    )


def _greedy_everywhere(game: AdversaryGame, q_min: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The learned values and proposals of every (k, state); 0 and -1 where no task is left."""
    levels, edge_start = game.budget + 1, game.mdp.edge_start
    values = np.zeros((levels, game.space.n_states))
    choice = np.full((levels, game.space.n_states), -1, dtype=np.int64)
    live = np.flatnonzero(np.diff(edge_start) > 0)
    for k in range(levels):
        values[k, live], choice[k, live] = _greedy(
            q_min, edge_start, game.mdp.n_edges, np.full(len(live), k), live
        )
    return values, choice


def minimax_policy(
    game: AdversaryGame, choice: np.ndarray, method: str, meta: dict | None = None
) -> Policy:
    """The policy file's form of the proposals at the full budget (k = K): a policy file maps a
    state to a task, without the mistakes left; `meta` records the budget."""
    meta = {"mistakes": game.budget, "gamma": game.gamma, **(meta or {})}
    return policy_from_choices(game.mdp, choice[game.budget], method, meta)
