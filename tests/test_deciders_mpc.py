"""The mpc decider's re-solve against a reference: plain Jacobi value iteration over the subtree
(the solver mpc used first), on the flange case and on a generated assembly, with and without
observations in the online operator model."""

from __future__ import annotations

import numpy as np
import pytest

from hrc_drake.evaluate import simulate_run
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import operator_seconds, table_from_seconds, task_edges, uniform_bets
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.mpc import MpcDecider, subtree_levels
from hrc_drake.tasks.spec import load_spec, parse_spec
from hrc_drake.tasks.tokens import UNDO


def reference_q(decider: MpcDecider, state: int, values: np.ndarray):
    """Jacobi value iteration over the subtree below `state`, one Python row per proposal:
    expected seconds of every answer the model gives, plus the price of the best bet."""
    space, mdp = decider.space, decider.mdp
    below = np.concatenate(subtree_levels(space, state))
    states = [int(s) for s in below if space.kind[s] != StateKind.TERMINAL]
    rows = {}
    for s in states:
        tasks = space.tasks(s)
        names = [t for t, _ in tasks]
        edges = list(mdp.edges_of(s))
        rows[s] = []
        for proposed in names:
            p = decider.model.outcome_probabilities(s, proposed)
            outcome = [
                (p[t], float(decider.cost[e]), int(mdp.edge_dst[e]))
                for t, e in zip(names, edges, strict=True)
            ]
            price = decider.bets.best_bet(space.sequence(s), p, proposed)[1]
            rows[s].append((outcome, price))
    values = values.copy()
    for _ in range(100_000):
        q = {
            s: [sum(pr * (c + values[d]) for pr, c, d in out) + pen for out, pen in rows[s]]
            for s in states
        }
        change = max(abs(min(q[s]) - values[s]) for s in states)
        for s in states:
            values[s] = min(q[s])
        if change < 1e-11:
            break
    return np.array(q[state])


def generated_space():
    """Five slots, three oval flanges, one square (as `benchmarks/generated.py` builds them)."""
    data = {
        "name": "generated-5slots-3F-1S",
        "base": {"slots": 5},
        "parts": {
            "F": {"count": 3, "footprint": 1},
            "S": {"count": 1, "footprint": 2, "host": {"tag": "0"}},
        },
        "mounts": [
            {"part": "F", "to": "base", "count": 2},
            {"part": "F", "to": "S", "count": 1},
            {"part": "S", "to": "base", "count": 1},
        ],
        "precedence": {"complete_first": ["S"]},
        "goal": {"min_gap": [{"parts": ["F", "F"], "slots": 2}]},
        "mistakes": [{"part": "F", "to": "S"}],
    }
    return generate_states(parse_spec(data, source=data["name"]))


def seconds_table(space):
    seconds = {}
    for state, task in task_edges(space):
        robot = 5.0 if task == UNDO else 5.0 + 0.1 * space.tokens.index(task)
        seconds[state, task] = robot + operator_seconds(space.spec, state, task)
    bets = uniform_bets(space, retarget=0.8, swap=4.0)
    return table_from_seconds(space, seconds, cell_hash="test", carry=(2.5, 4.0), bets=bets)


@pytest.fixture(scope="module", params=["flange", "generated"])
def case(request):
    if request.param == "flange":
        space = generate_states(load_spec(models_dir() / "assemblies" / "flange.yaml"))
    else:
        space = generated_space()
    return space, seconds_table(space)


def check_boundaries(decider, space, costs, operator, seen):
    """Play one run, checking the re-solve at every boundary against the reference."""
    index = 0
    for step in range(1, 40):
        if space.kind[index] == StateKind.TERMINAL:
            return
        before = decider.values.copy()
        edges, q = decider.q_values(index)
        expected = reference_q(decider, index, before)
        np.testing.assert_allclose(q, expected, atol=1e-5)
        assert list(edges) == list(decider.mdp.edges_of(index))
        state = space.sequence(index)
        proposal = decider.propose(state)
        assert q[[t for t, _ in space.tasks(index)].index(proposal)] <= q.min() + 1e-6
        performed = operator(step, state, proposal)
        decider.observe(state, proposal, performed)
        seen.add((proposal, performed))
        index = dict(space.tasks(index))[performed]


@pytest.mark.parametrize(
    ("population", "params"),
    [("mistake-prone", {"p": 0.5}), ("change-of-mind", {"p": 0.5}), ("habitual", {})],
)
def test_resolve_matches_reference_value_iteration(case, population, params):
    space, costs = case
    decider = MpcDecider(space, costs)
    seen = set()
    for i in range(3):
        operator = make_operator_model(population, space, seed=i, **params)
        check_boundaries(decider, space, costs, operator, seen)
    # The runs did deviate, so the learned corrections were exercised.
    assert any(p != d for p, d in seen)
    assert decider.model.observed_states()


def test_resolve_from_a_wrong_state_and_after_learning(case):
    space, costs = case
    decider = MpcDecider(space, costs)
    for i in range(5):
        simulate_run(space, costs, decider, make_operator_model("random", space, seed=i))
    wrong = int(np.flatnonzero(space.kind == StateKind.WRONG)[0])
    before = decider.values.copy()
    _, q = decider.q_values(wrong)
    np.testing.assert_allclose(q, reference_q(decider, wrong, before), atol=1e-5)
    for s in (0, int(space.first_child[0])):
        before = decider.values.copy()
        _, q = decider.q_values(s)
        np.testing.assert_allclose(q, reference_q(decider, s, before), atol=1e-5)
