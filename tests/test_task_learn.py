"""Q-learning: seeded, with a learning curve; our schedules are minimum-effort from every state,
the default one (`cover`) on larger specs too."""

from pathlib import Path

import numpy as np
import pytest

from hrc_drake.tasks.coverage import train_coverage
from hrc_drake.tasks.decide import minimum_effort_violations
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.learn import (
    CoverageSchedule,
    ExploringStartsSchedule,
    FullSchedule,
    PaperSchedule,
    train,
)
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import policy_from_choices
from hrc_drake.tasks.solve import greedy_choice, solve_exact, tasks_to_finish
from hrc_drake.tasks.spec import load_spec

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("seed", range(12))
def test_full_schedule_is_minimum_effort_from_every_state(flange_space, flange_mdp, seed):
    result = train(flange_mdp, FullSchedule(), seed=seed)
    policy = policy_from_choices(flange_mdp, result.choice, "q-learning/full")
    assert minimum_effort_violations(flange_space, policy) == {}


@pytest.mark.parametrize("seed", range(8))
def test_exploring_starts_schedule_is_minimum_effort_within_200_episodes(
    flange_space, flange_mdp, seed
):
    schedule = ExploringStartsSchedule()
    result = train(flange_mdp, schedule, seed=seed)
    policy = policy_from_choices(flange_mdp, result.choice, "q-learning/explore")
    assert minimum_effort_violations(flange_space, policy) == {}
    # One episode per non-terminal state per sweep (16 for the flange case), at most 10 sweeps.
    starts = int(np.sum(np.diff(flange_mdp.edge_start) > 0))
    assert starts == 16
    assert result.episodes % starts == 0 and result.episodes <= 200
    assert len(result.returns) == result.episodes


def test_exploring_starts_tries_every_task_of_every_state(flange_space):
    """Each state's first task is its least-tried one: after a sweep per task, all are tried."""
    mdp = build_mdp(flange_space, MdpConfig(mistake_prob=0.0))
    most = int(np.max(np.diff(mdp.edge_start)))
    schedule = ExploringStartsSchedule(min_sweeps=most, max_sweeps=most, epsilon0=0.0)
    result = train(mdp, schedule, seed=1)
    assert result.episodes == most * 16
    # Optimistic start at 2.0 (the terminal reward): a task worth less that still shows 2.0 was
    # never tried.
    exact = solve_exact(mdp).q
    assert not np.any((result.q == 2.0) & (exact < 2.0 - 1e-9))


def test_full_schedule_with_operator_overrides(flange_space):
    mdp = build_mdp(flange_space, MdpConfig(override_prob=0.1))
    result = train(mdp, FullSchedule(), seed=3)
    policy = policy_from_choices(mdp, result.choice, "q-learning/full")
    assert minimum_effort_violations(flange_space, policy) == {}


def test_same_seed_same_result(flange_mdp):
    for schedule in (PaperSchedule(), FullSchedule(), ExploringStartsSchedule()):
        a = train(flange_mdp, schedule, seed=5)
        b = train(flange_mdp, schedule, seed=5)
        assert np.array_equal(a.q, b.q) and np.array_equal(a.returns, b.returns)
    c = train(flange_mdp, PaperSchedule(), seed=6)
    assert not np.array_equal(a.returns, c.returns)


def test_paper_schedule_stops_on_the_moving_average(flange_mdp):
    schedule = PaperSchedule()
    result = train(flange_mdp, schedule, seed=0)
    # epsilon reaches 0 after 180 episodes; the stop rule needs two stable windows after that.
    assert 180 <= result.episodes < schedule.max_episodes
    average = result.moving_average(schedule.window)
    assert len(average) == result.episodes
    assert abs(average[-1] - average[-1 - schedule.window]) < schedule.stop_tolerance
    assert average[-1] == pytest.approx(result.returns[-20:].mean())


def test_paper_schedule_learns_the_optimal_sequence_from_the_start(flange_space, flange_mdp):
    """The paper's headline result: from the empty base the agent finishes in three tasks."""
    from hrc_drake.tasks.decide import run_decisions

    finished_in_three = 0
    for seed in range(10):
        result = train(flange_mdp, PaperSchedule(), seed=seed)
        policy = policy_from_choices(flange_mdp, result.choice, "q-learning/paper")
        states, _ = run_decisions(flange_space, policy)
        finished_in_three += len(states) == 4
    assert finished_in_three >= 8


def test_progress_is_reported(flange_mdp):
    calls = []
    train(
        flange_mdp,
        FullSchedule(min_sweeps=2, max_sweeps=3),
        seed=0,
        progress=lambda done, total, value: calls.append((done, total)),
    )
    assert calls and calls[-1][1] == 3


# --- the default schedule: exploring starts until every state is covered ---


def _locally_minimum_effort(mdp, choice) -> np.ndarray:
    """Non-terminal states whose chosen task does not lead one task closer to a terminal state
    (none: the greedy policy is minimum-effort from every state, by induction on the tasks
    left)."""
    best = tasks_to_finish(mdp.space)
    states = np.flatnonzero(np.diff(mdp.edge_start) > 0)
    return states[best[mdp.edge_dst[choice[states]]] != best[states] - 1]


@pytest.fixture(scope="module")
def two_host_mdp():
    """Four oval flanges on seven slots with two host flanges: 11,426 states."""
    space = generate_states(load_spec(DATA / "two-host-seven.yaml"))
    return build_mdp(space)


@pytest.mark.parametrize("seed", range(6))
def test_coverage_schedule_is_minimum_effort_from_every_state(flange_space, flange_mdp, seed):
    result = train(flange_mdp, CoverageSchedule(), seed=seed)
    assert result.converged and result.schedule == "cover"
    policy = policy_from_choices(flange_mdp, result.choice, "q-learning/cover")
    assert minimum_effort_violations(flange_space, policy) == {}
    assert len(result.returns) == result.rounds


@pytest.mark.parametrize(
    "config",
    [MdpConfig(), MdpConfig(mistake_prob=0.2), MdpConfig(override_prob=0.1)],
    ids=["mistakes", "more-mistakes", "overrides"],
)
def test_coverage_schedule_covers_every_state_of_a_larger_spec(two_host_mdp, config):
    """11,426 states, where `explore` (10 sweeps) leaves states off: the coverage schedule ends
    minimum-effort from every one of them, under mistakes and under overrides."""
    mdp = build_mdp(two_host_mdp.space, config)
    result = train(mdp, CoverageSchedule(), seed=2)
    assert result.converged
    assert len(_locally_minimum_effort(mdp, result.choice)) == 0


def test_coverage_stop_rule_is_coverage_not_a_count(two_host_mdp):
    """Learning ends on full sweeps that find the policy finishing everywhere and unchanged:
    `patience` of them after the first (which has nothing to compare with); capped before,
    the learner says it is not done."""
    capped = train(two_host_mdp, CoverageSchedule(max_rounds=1), seed=0)
    assert not capped.converged and capped.rounds == 1
    for patience in (2, 4):
        done = train_coverage(two_host_mdp, CoverageSchedule(patience=patience), seed=0)
        assert done.converged and done.full_sweeps >= patience + 1
        choice = greedy_choice(two_host_mdp, done.q, tie_tolerance=0.0)
        assert len(_locally_minimum_effort(two_host_mdp, choice)) == 0
        # Every full sweep starts an episode from every (state, task) pair.
        assert done.episodes > done.full_sweeps * two_host_mdp.n_edges


def test_coverage_schedule_same_seed_same_table(flange_mdp):
    a = train(flange_mdp, CoverageSchedule(), seed=4)
    b = train(flange_mdp, CoverageSchedule(), seed=4)
    assert np.array_equal(a.q, b.q) and a.episodes == b.episodes
    c = train(flange_mdp, CoverageSchedule(), seed=5)
    assert not np.array_equal(a.q, c.q)
