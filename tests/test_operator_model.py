"""The online operator model: Dirichlet counts per (state, proposed task), no Drake."""

from __future__ import annotations

import pytest

from hrc_drake.resources import models_dir
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.operator_model import OnlineOperatorModel
from hrc_drake.tasks.spec import load_spec

FLANGE = models_dir() / "assemblies" / "flange.yaml"


@pytest.fixture(scope="module")
def space():
    return generate_states(load_spec(FLANGE))


def test_prior_favours_following_and_sums_to_one(space):
    model = OnlineOperatorModel(space)
    p = model.outcome_probabilities((), "F1")
    assert set(p) == {t for t, _ in space.tasks(space.index(()))}
    assert max(p, key=p.get) == "F1"
    assert sum(p.values()) == pytest.approx(1.0)
    assert model.observed_states() == set()


def test_following_raises_the_follow_probability(space):
    model = OnlineOperatorModel(space)
    before = model.outcome_probabilities((), "F1")["F1"]
    for _ in range(5):
        model.update((), "F1", "F1")
    assert model.outcome_probabilities((), "F1")["F1"] > before
    assert model.observations((), "F1") == {"F1": 5.0}
    assert model.observed_states() == {space.index(())}


def test_without_pooling_a_habit_stays_with_its_proposal(space):
    model = OnlineOperatorModel(space, pool=0.0)
    for _ in range(10):
        model.update((), "F1", "S23")
    assert model.outcome_probabilities((), "F1")["S23"] > 0.6
    assert model.outcome_probabilities((), "F3")["F3"] > 0.9


def test_infeasible_proposal_and_bad_priors_are_errors(space):
    model = OnlineOperatorModel(space)
    with pytest.raises(KeyError, match="not feasible"):
        model.outcome_probabilities((), "no-such-task")
    with pytest.raises(ValueError, match="follow_prior > 0"):
        OnlineOperatorModel(space, follow_prior=0.0)
