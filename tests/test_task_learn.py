"""Q-learning: seeded, with a learning curve; our schedule is minimum-effort from every state."""

import numpy as np
import pytest

from hrc_drake.tasks.decide import minimum_effort_violations
from hrc_drake.tasks.learn import ExploringStartsSchedule, FullSchedule, PaperSchedule, train
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import policy_from_choices
from hrc_drake.tasks.solve import solve_exact


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
