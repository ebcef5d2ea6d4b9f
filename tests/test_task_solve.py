"""Exact solutions: minimum effort from every state, Table 2's right-hand column."""

import numpy as np
import pytest
from flange_data import TABLE2, TASKS_TO_FINISH

from hrc_drake.hri.operator import ScriptedOperator, parse_operator_script
from hrc_drake.tasks.decide import minimum_effort_violations, run_decisions
from hrc_drake.tasks.graph import StateKind
from hrc_drake.tasks.mdp import MdpConfig, Rewards, build_mdp
from hrc_drake.tasks.solve import exact_policy, solve_exact, tasks_to_finish


def test_tasks_to_finish_matches_the_spec(flange_space):
    best = tasks_to_finish(flange_space)
    got = {
        flange_space.name(s): int(best[s])
        for s in range(flange_space.n_states)
        if flange_space.kind[s] != StateKind.TERMINAL
    }
    assert got == TASKS_TO_FINISH


def test_mistake_transitions_as_read_in_the_spec(flange_space, flange_mdp):
    mdp = flange_mdp
    s7 = flange_space.index(("F1", "S23"))
    edge = next(e for e in mdp.edges_of(s7) if mdp.task_name(e) == "F03")
    outcomes = {
        flange_space.name(int(mdp.out_dst[o])): float(mdp.out_prob[o])
        for o in range(mdp.out_start[edge], mdp.out_start[edge + 1])
    }
    assert outcomes == pytest.approx({"10": 0.95, "9": 0.05})
    s1 = 0  # placements on the base are not mistake-prone
    for e in mdp.edges_of(s1):
        assert mdp.out_start[e + 1] - mdp.out_start[e] == 1


@pytest.mark.parametrize(
    "config",
    [
        MdpConfig(),
        MdpConfig(mistake_prob=0.0),
        MdpConfig(gamma=1.0),
        MdpConfig(override_prob=0.1),
        MdpConfig(mistake_prob=0.2, gamma=0.9),
    ],
)
def test_exact_policy_is_minimum_effort_from_every_state(flange_space, config):
    assert minimum_effort_violations(flange_space, exact_policy(flange_space, config)) == {}


@pytest.mark.parametrize(("script", "published", "minimum"), TABLE2)
def test_table2_rows_follow_the_minimum_effort_column(flange_space, script, published, minimum):
    policy = exact_policy(flange_space)
    states, _ = run_decisions(flange_space, policy, ScriptedOperator(parse_operator_script(script)))
    names = [flange_space.name(flange_space.index(s)) for s in states]
    assert names == minimum.split()


def test_exact_values_satisfy_bellman(flange_mdp):
    solution = solve_exact(flange_mdp)
    for s in range(flange_mdp.space.n_states):
        edges = flange_mdp.edges_of(s)
        if len(edges):
            assert solution.values[s] == pytest.approx(max(solution.q[e] for e in edges))


def test_task_costs_break_ties_by_duration(flange_space):
    costs = {
        "F1": 5.0,
        "F2": 5.0,
        "F3": 5.0,
        "F01": 5.0,
        "F02": 5.0,
        "F03": 5.0,
        "S12": 6.0,
        "S23": 9.0,
        "undo": 4.0,
    }
    config = MdpConfig(rewards=Rewards(task_costs=costs, terminal_bonus=10.0))
    policy = exact_policy(flange_space, config)
    # S23 costs more than S12: start with the sequence that uses S12.
    assert policy.next_task(()) in {"F3", "S12"}
    with pytest.raises(KeyError, match="no entry for 'F1'"):
        build_mdp(flange_space, MdpConfig(rewards=Rewards(task_costs={"S12": 1.0})))


def test_solver_is_deterministic(flange_mdp):
    a, b = solve_exact(flange_mdp), solve_exact(flange_mdp)
    assert np.array_equal(a.choice, b.choice) and np.array_equal(a.values, b.values)
