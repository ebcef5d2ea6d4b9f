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

Slips are pooled over the states: a placement the spec lists under ``mistakes`` that lands in
another seat of its kind (the same part on the same kind of host) counts toward one slip rate per
kind, and in every state where the operator has been seen the model adds pseudo-observations at
that rate to the proposal's answers: as many as the proposals of that kind seen anywhere, at most
`slip_pool` (a slip is a property of the operator's hand, not of the state: a state visited a
few dozen times would otherwise keep the slip rate of its few visits). The pooled rate has the
prior's mean, ``other_prior / (follow_prior + other_prior)``, with that many pseudo-counts.
States not seen yet keep the prior.
"""

from __future__ import annotations

from collections import defaultdict

from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

# Pseudo-observations at the pooled slip rate added in every state seen: enough to outweigh the
# noise of a state's few dozen visits, little beside the hundreds of a state visited daily.
SLIP_POOL = 100.0


class OnlineOperatorModel:
    """Dirichlet-multinomial counts of the performed task per (state, proposed task)."""

    def __init__(
        self,
        space: StateSpace,
        follow_prior: float = 4.0,
        other_prior: float = 0.05,
        pool: float = 1.0,
        slip_pool: float = SLIP_POOL,
    ):
        if follow_prior <= 0 or other_prior < 0 or pool < 0 or slip_pool < 0:
            raise ValueError(
                f"priors must be follow_prior > 0, other_prior >= 0, pool >= 0 and slip_pool "
                f">= 0, got {follow_prior}, {other_prior}, {pool} and {slip_pool}"
            )
        self.space = space
        self.follow_prior = float(follow_prior)
        self.other_prior = float(other_prior)
        self.pool = float(pool)
        self.slip_pool = float(slip_pool)
        self.counts: dict[tuple[int, str], dict[str, float]] = defaultdict(dict)
        self.deviations: dict[int, dict[str, float]] = defaultdict(dict)
        self.seen: set[int] = set()
        # Per mount kind prone to mistakes: [proposals, slips] over every state.
        self.slips: dict[int, list[float]] = {}

    def _state(self, state: int | tuple[str, ...]) -> int:
        return state if isinstance(state, int) else self.space.index(state)

    def update(
        self, state: int | tuple[str, ...], proposed: str, performed: str, count: float = 1.0
    ) -> None:
        """Count one observation (or `count` alike): in `state` the robot proposed `proposed`,
        the cell observed `performed` (equal when the operator followed)."""
        s = self._state(state)
        row = self.counts[s, proposed]
        row[performed] = row.get(performed, 0.0) + count
        if performed != proposed:
            pooled = self.deviations[s]
            pooled[performed] = pooled.get(performed, 0.0) + count
        self.seen.add(s)
        slip = self._slip_kind(s, proposed)
        if slip is not None:
            tally = self.slips.setdefault(slip[0], [0.0, 0.0])
            tally[0] += count
            tally[1] += count if performed in slip[1] else 0.0

    def _slip_kind(self, s: int, proposed: str) -> tuple[int, list[str]] | None:
        """The mount kind of a proposal prone to mistakes and its other seats in state `s`
        (None: the proposal cannot slip)."""
        if proposed == UNDO:
            return None
        spec, table = self.space.spec, self.space.table
        mount = int(table.mount[table.tokens.index(proposed)])
        m = spec.mounts[mount]
        if (m.part, m.on) not in spec.mistakes:
            return None
        seats = [
            t
            for t, _ in self.space.tasks(s)
            if t not in (proposed, UNDO) and int(table.mount[table.tokens.index(t)]) == mount
        ]
        return (mount, seats) if seats else None

    def copy(self) -> OnlineOperatorModel:
        """An independent copy of the counts (the state space is shared)."""
        other = OnlineOperatorModel(
            self.space, self.follow_prior, self.other_prior, self.pool, self.slip_pool
        )
        for key, row in self.counts.items():
            other.counts[key] = dict(row)
        for key, row in self.deviations.items():
            other.deviations[key] = dict(row)
        other.seen = set(self.seen)
        for key, tally in self.slips.items():
            other.slips[key] = list(tally)
        return other

    def records(self) -> list[tuple[tuple[str, ...], str, str, float]]:
        """Every count as (state, proposed, performed, count), in a stable order."""
        rows = [
            (self.space.sequence(s), proposed, performed, count)
            for (s, proposed), row in self.counts.items()
            for performed, count in row.items()
        ]
        return sorted(rows, key=lambda r: (len(r[0]), r[:3]))

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
        slip = self._slip_kind(s, proposed) if self.slip_pool and s in self.seen else None
        if slip is not None and self.slips.get(slip[0], [0.0])[0] > 0:
            proposals, slips = self.slips[slip[0]]
            # The pooled rate under the prior's (other / (follow + other)), and worth no more
            # pseudo-observations than the proposals it was learned from.
            strength = self.follow_prior + self.other_prior
            rate = (slips + self.other_prior) / (proposals + strength)
            weight = min(self.slip_pool, proposals)
            weights[proposed] += weight * (1.0 - rate)
            for t in slip[1]:
                weights[t] += weight * rate / len(slip[1])
        total = sum(weights.values())
        return {t: w / total for t, w in weights.items()}
