"""What the operator does when the robot proposes a task, learned online (no Drake).

Counts, per (state, proposed task), of the task the operator performed — the proposal
(followed) or another one (an override, a misplacement, an undo) — with a Dirichlet prior:
`follow_prior` pseudo-counts on following, `other_prior` on each other feasible task. The
posterior mean gives the probabilities the model-predictive decider plans with.

Answers are pooled over the proposals of a state: a task the operator performed in a state
instead of some proposal adds `pool` pseudo-counts to that task for every other proposal of the
state. An operator who always starts with the same part whatever the robot proposes is thus
expected to do so after a proposal not tried yet (a habit is a property of the state, not of
the proposal).
"""

from __future__ import annotations

from collections import defaultdict

from hrc_drake.tasks.graph import StateSpace


class OnlineOperatorModel:
    """Dirichlet-multinomial counts of the performed task per (state, proposed task)."""

    def __init__(
        self,
        space: StateSpace,
        follow_prior: float = 4.0,
        other_prior: float = 0.05,
        pool: float = 1.0,
    ):
        if follow_prior <= 0 or other_prior < 0 or pool < 0:
            raise ValueError(
                f"priors must be follow_prior > 0, other_prior >= 0 and pool >= 0, got "
                f"{follow_prior}, {other_prior} and {pool}"
            )
        self.space = space
        self.follow_prior = float(follow_prior)
        self.other_prior = float(other_prior)
        self.pool = float(pool)
        self.counts: dict[tuple[int, str], dict[str, float]] = defaultdict(dict)
        self.deviations: dict[int, dict[str, float]] = defaultdict(dict)

    def _state(self, state: int | tuple[str, ...]) -> int:
        return state if isinstance(state, int) else self.space.index(state)

    def update(self, state: int | tuple[str, ...], proposed: str, performed: str) -> None:
        """Count one observation: in `state` the robot proposed `proposed`, the cell observed
        `performed` (equal when the operator followed)."""
        s = self._state(state)
        row = self.counts[s, proposed]
        row[performed] = row.get(performed, 0.0) + 1.0
        if performed != proposed:
            pooled = self.deviations[s]
            pooled[performed] = pooled.get(performed, 0.0) + 1.0

    def observed_states(self) -> set[int]:
        """States with at least one observation."""
        return {s for s, _ in self.counts}

    def observations(self, state: int | tuple[str, ...], proposed: str) -> dict[str, float]:
        """Counts seen so far at (state, proposed), without the prior."""
        return dict(self.counts.get((self._state(state), proposed), {}))

    def outcome_probabilities(
        self, state: int | tuple[str, ...], proposed: str
    ) -> dict[str, float]:
        """Posterior mean probability of each feasible task being performed when `proposed` is
        proposed in `state`; KeyError naming the task if it is not feasible there."""
        s = self._state(state)
        tasks = [t for t, _ in self.space.tasks(s)]
        if proposed not in tasks:
            raise KeyError(f"task {proposed!r} is not feasible in state {self.space.sequence(s)}")
        seen = self.counts.get((s, proposed), {})
        pooled = self.deviations.get(s, {})
        weights = {}
        for t in tasks:
            if t == proposed:
                weights[t] = self.follow_prior + seen.get(t, 0.0)
            else:
                # Deviations to t seen after other proposals of this state.
                elsewhere = pooled.get(t, 0.0) - seen.get(t, 0.0)
                weights[t] = self.other_prior + seen.get(t, 0.0) + self.pool * elsewhere
        total = sum(weights.values())
        return {t: w / total for t, w in weights.items()}
