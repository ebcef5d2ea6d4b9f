"""A policy scored against the exact solution: minimum effort, loops, value gap.

Following a policy with no deviation is a walk on a functional graph over state ids (each
state's proposal leads to one child, or to the parent by undo; `next_states`). Pointer doubling
on that graph gives, for every state at once and in O(n log n), whether the walk reaches a
terminal state and in how many tasks: compared with `tasks_to_finish` (the fewest), it says
where the policy is not minimum-effort (ties count as equal) and where it loops. The value gap
is the exact optimal value minus the policy's own value under the same `MdpConfig` (operator
mistakes and overrides included), per state.

`load_runnable_policy` is how a policy file enters a run (`react`, `table2`, `simulate` and
every cell run of a scenario's policy): a policy that never finishes from some state is refused
there with one line, before anything is built.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from hrc_drake.resources import default_assembly
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.mdp import MdpConfig, SequenceMDP, build_mdp
from hrc_drake.tasks.policy import Policy, PolicyFileError, load_policy, next_states
from hrc_drake.tasks.solve import solve_exact, tasks_to_finish


@dataclass(frozen=True, eq=False)
class Walks:
    """Where following a policy with no deviation leads, from every state."""

    steps: np.ndarray  # tasks to a terminal state; -1 where the walk never gets there
    loops: np.ndarray  # bool: the walk enters a cycle (else it may end where it has no task)

    @property
    def finishes(self) -> np.ndarray:
        """Whether the walk from each state reaches a terminal state."""
        return self.steps >= 0


def follow(space: StateSpace, next_state: np.ndarray) -> Walks:
    """The walks of the functional graph `next_state` (`next_states`) from every state.

    Terminal states and states with no successor (-1) absorb the walk; after k doublings each
    state knows where it is 2^k tasks later and how many of those tasks were done before
    absorption. A walk that reaches a terminal state does so without repeating a state, in fewer
    than n tasks, so ceil(log2 n) + 1 doublings decide every state.
    """
    n = space.n_states
    ids = np.arange(n, dtype=np.int64)
    terminal = space.kind == StateKind.TERMINAL
    dead = ~terminal & (next_state < 0)
    absorbing = terminal | dead
    jump = np.where(absorbing, ids, next_state)
    count = (~absorbing).astype(np.int64)
    for _ in range(int(np.ceil(np.log2(max(n, 2)))) + 1):
        count = count + count[jump]
        jump = jump[jump]
    finishes = terminal[jump]
    return Walks(steps=np.where(finishes, count, -1), loops=~absorbing[jump])


@dataclass(frozen=True, eq=False)
class PolicyCheck:
    """A policy scored on every state of a space (arrays indexed by state id)."""

    space: StateSpace
    next_state: np.ndarray  # the proposal's state, -1 where there is none (`next_states`)
    walks: Walks
    fewest: np.ndarray  # `tasks_to_finish`
    config: MdpConfig | None = None
    values: np.ndarray | None = None  # exact optimal values under `config`
    policy_values: np.ndarray | None = None  # the policy's own; -inf: it never finishes

    @property
    def non_terminal(self) -> np.ndarray:
        """States where the episode goes on."""
        return self.space.kind != StateKind.TERMINAL

    @property
    def missing(self) -> np.ndarray:
        """Non-terminal states where the policy gives no (feasible) task."""
        return self.non_terminal & (self.next_state < 0)

    @property
    def not_minimum(self) -> np.ndarray:
        """Non-terminal states from which following the policy does not take the fewest tasks
        (judged by the number of tasks: another route of the same length is minimum-effort)."""
        reachable = self.fewest >= 0
        return self.non_terminal & reachable & (self.walks.steps != self.fewest)

    @property
    def unfinished(self) -> np.ndarray:
        """Non-terminal states from which following the policy never reaches a terminal state
        (it loops, or reaches a state it gives no task)."""
        return self.non_terminal & ~self.walks.finishes

    @property
    def gap(self) -> np.ndarray | None:
        """Exact value minus the policy's value, per state (inf where the policy's expected
        return diverges; 0 within the solvers' tolerance); None when values were not computed."""
        if self.values is None or self.policy_values is None:
            return None
        gap = self.values - self.policy_values
        return np.where(gap > 1e-9 * np.maximum(1.0, np.abs(self.values)), gap, 0.0)

    def summary(self) -> dict:
        """Counts and the value gap (start, max with where, mean over non-terminal states)."""
        space = self.space
        out = {
            "states": space.n_states,
            "non_terminal": int(self.non_terminal.sum()),
            "minimum_effort": int((self.non_terminal & ~self.not_minimum).sum()),
            "not_minimum_effort": int(self.not_minimum.sum()),
            "loops": int((self.non_terminal & self.walks.loops).sum()),
            "missing": int(self.missing.sum()),
            "start_tasks": int(self.walks.steps[0]) if self.walks.steps[0] >= 0 else None,
            "start_fewest": int(self.fewest[0]),
        }
        gap = self.gap
        if gap is not None and self.config is not None:
            inner = gap[self.non_terminal]
            worst = int(np.flatnonzero(self.non_terminal)[np.argmax(inner)])
            out["value_gap"] = {
                "gamma": self.config.gamma,
                "mistake_prob": self.config.mistake_prob,
                "start": _number(gap[0]),
                "max": _number(gap[worst]),
                "max_at": list(space.sequence(worst)) if gap[worst] > 0 else None,
                "mean": _number(float(inner[np.isfinite(inner)].mean())),
                "infinite": int(np.isinf(inner).sum()),
            }
        return out


def _number(x: float) -> float | None:
    """A JSON-safe figure: None for infinity (the policy's return diverges there)."""
    return None if not np.isfinite(x) else float(x)


def check_policy(
    space: StateSpace,
    policy: Policy | np.ndarray,
    config: MdpConfig | None = None,
    values: bool = True,
) -> PolicyCheck:
    """Score `policy` (a Policy, or its `next_states` array) on every state of `space`: walks,
    minimum effort and, with `values`, the value gap under `config` (default MdpConfig())."""
    next_state = policy if isinstance(policy, np.ndarray) else next_states(space, policy)
    walks = follow(space, next_state)
    fewest = tasks_to_finish(space)
    if not values:
        return PolicyCheck(space, next_state, walks, fewest)
    mdp = build_mdp(space, config or MdpConfig())
    optimal = solve_exact(mdp).values
    own = policy_values(mdp, next_state, start=optimal)
    return PolicyCheck(space, next_state, walks, fewest, mdp.config, optimal, own)


def policy_values(
    mdp: SequenceMDP,
    next_state: np.ndarray,
    start: np.ndarray | None = None,
    tolerance: float = 1e-10,
    max_iterations: int = 1_000_000,
) -> np.ndarray:
    """The policy's expected discounted return from every state, as the MDP's operator plays
    it (mistakes and overrides): iterative policy evaluation on the sparse matrix of the
    policy's outcomes (one matrix-vector product per sweep). -inf where the return diverges (an
    undiscounted MDP, and a positive chance of never finishing); a state with no task counts as
    never finishing. Started from `start` (the optimal values: the sweeps then only descend).
    """
    space, config = mdp.space, mdp.config
    n = space.n_states
    chosen = np.full(n, -1, dtype=np.int64)
    match = mdp.edge_dst == next_state[mdp.edge_src]
    chosen[mdp.edge_src[match]] = np.flatnonzero(match)
    counts = np.diff(mdp.edge_start)[mdp.edge_src]
    is_chosen = chosen[mdp.edge_src] == np.arange(mdp.n_edges)
    p = config.override_prob
    # Weight of each edge in the state's expected return: the proposal, or an override.
    weight = np.where(
        is_chosen,
        np.where(counts > 1, 1.0 - p, 1.0),
        np.where(counts > 1, p / np.maximum(counts - 1, 1), 0.0),
    )
    weight[chosen[mdp.edge_src] < 0] = 0.0
    edge_of = np.repeat(np.arange(mdp.n_edges), np.diff(mdp.out_start))
    w = weight[edge_of] * mdp.out_prob
    keep = w > 0
    rows, cols, w = mdp.edge_src[edge_of[keep]], mdp.out_dst[keep], w[keep]
    reward = np.bincount(rows, weights=w * mdp.out_reward[keep], minlength=n)
    transitions = sp.csr_matrix((w * config.gamma, (rows, cols)), shape=(n, n))
    terminal = space.kind == StateKind.TERMINAL
    diverges = ~terminal & (chosen < 0)
    if config.gamma >= 1.0:  # discounted, every other return is finite
        diverges |= _never_sure_to_finish(transitions, terminal)
    if np.any(diverges):
        # States that may reach a diverging one diverge too: cut them out of the sweeps.
        diverges = _reaching(transitions, diverges)
        transitions = sp.diags((~diverges).astype(float)) @ transitions
    values = np.zeros(n) if start is None else np.array(start, dtype=float)
    values[terminal | diverges] = 0.0
    for _ in range(max_iterations):
        new = reward + transitions @ values
        new[terminal | diverges] = 0.0
        change = float(np.max(np.abs(new - values))) if n else 0.0
        values = new
        if change < tolerance:
            break
    else:
        raise RuntimeError(f"policy evaluation did not converge in {max_iterations} sweeps")
    values[diverges] = -np.inf
    return values


def _reaching(transitions: sp.csr_matrix, targets: np.ndarray) -> np.ndarray:
    """States from which `targets` are reached with positive probability (targets included):
    one breadth-first search on the reversed outcome graph from a node joined to every target."""
    n = transitions.shape[0]
    reverse = (transitions.T != 0).tocoo()
    graph = sp.csr_matrix(
        (
            np.ones(reverse.nnz + int(targets.sum())),
            (
                np.concatenate([reverse.row, np.full(int(targets.sum()), n)]),
                np.concatenate([reverse.col, np.flatnonzero(targets)]),
            ),
        ),
        shape=(n + 1, n + 1),
    )
    seen = breadth_first_order(graph, n, directed=True, return_predecessors=False)
    out = np.zeros(n, dtype=bool)
    out[seen[seen < n]] = True
    return out


def _never_sure_to_finish(transitions: sp.csr_matrix, terminal: np.ndarray) -> np.ndarray:
    """States that may, with positive probability, reach a state from which no terminal state
    can be reached: without discount their expected return diverges."""
    can_finish = _reaching(transitions, terminal)
    return _reaching(transitions, ~can_finish)


def exact_next_states(space: StateSpace, config: MdpConfig | None = None) -> np.ndarray:
    """`next_states` of the exact policy under `config`, straight from the solver's choices
    (no Policy, no dictionary of sequences: what `hrc-drake policy` lists at any size)."""
    mdp = build_mdp(space, config or MdpConfig())
    choice = solve_exact(mdp).choice
    return np.where(choice >= 0, mdp.edge_dst[np.maximum(choice, 0)], -1)


def refuse_unfinished(space: StateSpace, policy: Policy, source: str, check_hint: str) -> None:
    """PolicyFileError (one line) if following `policy` never reaches a terminal state from
    some state: every state is reachable through the operator's deviations, so a run could get
    there. Names the shallowest such state, how many there are and `check_hint`, the command
    that lists them."""
    walks = follow(space, next_states(space, policy))
    bad = np.flatnonzero((space.kind != StateKind.TERMINAL) & ~walks.finishes)
    if not len(bad):
        return
    first = int(bad[0])
    count = f"{len(bad):,} state{'s' if len(bad) > 1 else ''}"
    how = "loops" if walks.loops[first] else "gives no feasible task on the way"
    raise PolicyFileError(
        f"policy {source} {how}: following it from {count} never reaches a terminal state "
        f"(e.g. from {list(space.sequence(first))}); `{check_hint}` lists them; use a policy "
        "that finishes (`hrc-drake solve`, or train again)"
    )


def load_runnable_policy(path: str | Path, space: StateSpace) -> Policy:
    """`load_policy`, refusing a policy that never finishes from some state
    (`refuse_unfinished`): the one way a policy file enters a run."""
    policy = load_policy(path, space)
    refuse_unfinished(space, policy, f"file {path}", check_command(path, space))
    return policy


def check_command(path: str | Path, space: StateSpace) -> str:
    """The `hrc-drake check-policy` command line for the policy file `path` of `space`."""
    spec = space.spec
    same = spec.source and Path(spec.source).resolve() == Path(default_assembly()).resolve()
    assembly = "" if same or not spec.source else f" --assembly {spec.source}"
    return f"hrc-drake check-policy --policy {path}{assembly}"
