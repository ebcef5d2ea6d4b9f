"""The assembly MDP as a Gymnasium environment (optional extra: ``pip install hrc_drake[gym]``).

`AssemblyEnv` is the sequence MDP of `hrc_drake.tasks` where RL libraries expect it:

- **Observations**: ``Discrete(n_states)``, the state id (0 = the empty base; ids as in
  `StateSpace`, ``env.unwrapped.space.sequence(obs)`` gives the task sequence).
- **Actions**: ``Discrete(n_tokens + 1)``: action ``i < n_tokens`` proposes placement
  ``env.unwrapped.tasks[i]`` (the spec's tokens in canonical order), the last action proposes
  ``undo``. The meaning of an action is the same in every state.
- **Feasible actions**: ``info["action_mask"]`` (``np.int8``, 1 = feasible), as in Gymnasium's
  Taxi; also ``env.unwrapped.action_mask(state)``. An infeasible action is a no-op: the state
  does not change, the reward is `invalid_penalty` (default -1, a wasted task), and
  ``info["infeasible"]`` is True; it is not an error, so that samplers and checkers that draw
  any action work.
- **Randomness** is the operator: with ``config.override_prob`` the operator performs another
  feasible task (uniformly) instead of the proposed one, and a placement named in the spec's
  ``mistakes`` lands in the other free seat with ``config.mistake_prob``. A custom operator can
  be passed as a callable ``operator(state_sequence, proposed_task, feasible_tasks, rng) ->
  performed_task`` (it replaces the overrides; mistakes still apply to what it performs).
- **Rewards**: the MDP's: -1 per task and +2 on reaching a terminal state, or minus the seconds
  of each task edge when a cost table is given (``costs=``).
- **Episodes** end (``terminated``) in a terminal state (complete and correct), and are
  truncated after `max_steps` actions.
- ``env.unwrapped.P[s][a]`` is a list of ``(probability, next_state, reward, terminated)``, as in
  FrozenLake and Taxi, for the built-in operator model (`config`); a terminal state loops on
  itself with reward 0 and ``terminated`` True.

``reset(options={"state": s})`` starts in state `s` (an id or a task sequence): exploring starts.
Registered as ``"hrc_drake/Assembly-v0"`` when this module is imported. Gymnasium 1.x loads no
plugin entry points, so without importing it first, name the module in the id:
``gymnasium.make("hrc_drake.gym:hrc_drake/Assembly-v0")`` imports it, then makes the environment.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
except ImportError as err:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "hrc_drake.gym needs Gymnasium: pip install 'hrc_drake[gym]' (or pip install gymnasium)"
    ) from err

from hrc_drake.tasks.graph import StateKind, StateSpace, generate_states
from hrc_drake.tasks.mdp import UNDO_INDEX, EdgeCosts, MdpConfig, build_mdp
from hrc_drake.tasks.solve import timed_config
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

ENV_ID = "hrc_drake/Assembly-v0"

Operator = Callable[[tuple[str, ...], str, list[str], np.random.Generator], str]


class AssemblyEnv(gymnasium.Env):
    """The assembly sequence MDP: the agent proposes tasks, the operator performs them."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(
        self,
        assembly: str | Path | None = None,
        *,
        space: StateSpace | None = None,
        config: MdpConfig | None = None,
        costs: EdgeCosts | None = None,
        operator: Operator | None = None,
        invalid_penalty: float = -1.0,
        max_steps: int = 100,
        render_mode: str | None = None,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}: use None or 'ansi'")
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        self.space = space if space is not None else generate_states(load_spec(assembly))
        if costs is not None:
            config = timed_config(costs, config)
        self.mdp = build_mdp(self.space, config)
        self.config = self.mdp.config
        self.operator = operator
        self.invalid_penalty = float(invalid_penalty)
        self.max_steps = max_steps
        self.render_mode = render_mode
        self.tasks: tuple[str, ...] = (*self.space.tokens, UNDO)
        self.observation_space = spaces.Discrete(self.space.n_states)
        self.action_space = spaces.Discrete(len(self.tasks))
        mdp = self.mdp
        # edge_of[s, a]: the MDP edge of action a in state s (-1: infeasible).
        self._edge_of = np.full((self.space.n_states, len(self.tasks)), -1, dtype=np.int64)
        action = np.where(mdp.edge_task == UNDO_INDEX, len(self.tasks) - 1, mdp.edge_task)
        self._edge_of[mdp.edge_src, action] = np.arange(mdp.n_edges)
        self._terminal = self.space.kind == StateKind.TERMINAL
        self.P = self._transitions()
        self.s = 0
        self.steps = 0
        self.lastaction: int | None = None

    def action_mask(self, state: int) -> np.ndarray:
        """1 for each action feasible in `state`, else 0 (np.int8; none in a terminal state)."""
        return (self._edge_of[state] >= 0).astype(np.int8)

    def _outcomes(self, edge: int):
        mdp = self.mdp
        for o in range(int(mdp.out_start[edge]), int(mdp.out_start[edge + 1])):
            yield float(mdp.out_prob[o]), int(mdp.out_dst[o]), float(mdp.out_reward[o])

    def _transitions(self) -> dict[int, dict[int, list[tuple[float, int, float, bool]]]]:
        mdp, p = self.mdp, self.config.override_prob
        table: dict[int, dict[int, list[tuple[float, int, float, bool]]]] = {}
        for s in range(self.space.n_states):
            edges = list(mdp.edges_of(s))
            table[s] = {}
            for a in range(len(self.tasks)):
                if self._terminal[s]:
                    table[s][a] = [(1.0, s, 0.0, True)]
                    continue
                edge = int(self._edge_of[s, a])
                if edge < 0:
                    table[s][a] = [(1.0, s, self.invalid_penalty, False)]
                    continue
                merged: dict[tuple[int, float], float] = {}
                for performed in edges:
                    if len(edges) == 1 or p == 0.0:
                        weight = 1.0 if performed == edge else 0.0
                    else:
                        weight = 1.0 - p if performed == edge else p / (len(edges) - 1)
                    if weight == 0.0:
                        continue
                    for prob, dst, reward in self._outcomes(performed):
                        key = (dst, reward)
                        merged[key] = merged.get(key, 0.0) + weight * prob
                table[s][a] = [
                    (prob, dst, reward, bool(self._terminal[dst]))
                    for (dst, reward), prob in merged.items()
                ]
        return table

    def _info(self, **extra: Any) -> dict[str, Any]:
        return {"action_mask": self.action_mask(self.s), **extra}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode in the empty base, or in ``options["state"]`` (id or sequence)."""
        super().reset(seed=seed)
        state = (options or {}).get("state", 0)
        if not isinstance(state, int | np.integer):
            state = self.space.index(tuple(state))
        if not 0 <= int(state) < self.space.n_states:
            raise ValueError(
                f"options['state'] = {state}: not a state id (0 .. {self.space.n_states - 1})"
            )
        self.s, self.steps, self.lastaction = int(state), 0, None
        return self.s, self._info(prob=1.0)

    def _perform(self, edge: int) -> int:
        """The edge the operator performs when `edge` is proposed."""
        mdp, rng = self.mdp, self.np_random
        edges = list(mdp.edges_of(self.s))
        if self.operator is not None:
            sequence = self.space.sequence(self.s)
            feasible = [mdp.task_name(e) for e in edges]
            task = self.operator(sequence, mdp.task_name(edge), feasible, rng)
            if task not in feasible:
                raise ValueError(
                    f"operator performed {task!r} in {list(sequence)}, where the feasible tasks "
                    f"are {feasible}; an operator must return one of them"
                )
            return edges[feasible.index(task)]
        p = self.config.override_prob
        if p > 0 and len(edges) > 1 and rng.random() < p:
            others = [e for e in edges if e != edge]
            return others[int(rng.integers(len(others)))]
        return edge

    def step(self, action: int):
        """Propose task `action`; returns (state, reward, terminated, truncated, info)."""
        action = int(action)
        if not self.action_space.contains(action):
            raise ValueError(f"action {action} is outside Discrete({self.action_space.n})")
        self.lastaction = action
        if self._terminal[self.s]:
            return self.s, 0.0, True, False, self._info(prob=1.0, infeasible=False)
        self.steps += 1
        truncated = self.steps >= self.max_steps
        edge = int(self._edge_of[self.s, action])
        if edge < 0:
            info = self._info(prob=1.0, infeasible=True, task=None)
            return self.s, self.invalid_penalty, False, truncated, info
        performed = self._perform(edge)
        mdp = self.mdp
        lo, hi = int(mdp.out_start[performed]), int(mdp.out_start[performed + 1])
        cum = np.cumsum(mdp.out_prob[lo:hi])
        o = lo + min(int(np.searchsorted(cum, self.np_random.random(), side="right")), hi - lo - 1)
        self.s = int(mdp.out_dst[o])
        reward = float(mdp.out_reward[o])
        terminated = bool(self._terminal[self.s])
        info = self._info(
            prob=float(mdp.out_prob[o]),
            infeasible=False,
            task=mdp.task_name(performed),
            proposed=mdp.task_name(edge),
        )
        return self.s, reward, terminated, truncated and not terminated, info

    def render(self) -> str | None:
        """'ansi': a line with the state, its kind and feasible tasks (None without a mode)."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() without a render_mode: use render_mode='ansi'")
            return None
        seq = " ".join(self.space.sequence(self.s)) or "(empty base)"
        feasible = [self.tasks[a] for a in np.flatnonzero(self.action_mask(self.s))]
        last = "" if self.lastaction is None else f" after proposing {self.tasks[self.lastaction]}"
        return (
            f"state {self.space.name(self.s)}: {seq} [{self.space.state_kind(self.s).label}]"
            f"{last}; feasible: {', '.join(feasible) or '-'}\n"
        )


if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="hrc_drake.gym:AssemblyEnv")
