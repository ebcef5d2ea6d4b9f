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


def test_slips_are_pooled_over_the_states_seen(space):
    """Flanges slipping to the other row of the square in one state make a slip likely in
    another state seen (a property of the operator's hand), not in a state never seen; and the
    pooled rate weighs no more than the proposals it came from."""
    model = OnlineOperatorModel(space)
    square_12, square_23 = ("S12",), ("S23",)
    model.update(square_23, "F02", "F02")  # seen once, no slip there
    before = model.outcome_probabilities(square_23, "F02")["F03"]
    for answer in ["F02"] * 4 + ["F01"] * 16:  # F01 proposed 20 times, slipped to F02 4 times
        model.update(square_12, "F01", answer if answer == "F02" else "F01")
    after = model.outcome_probabilities(square_23, "F02")["F03"]
    assert before < 0.02 and 0.1 < after < 0.25
    unseen = ("F1", "S23")  # the same kind of proposal, never seen in this state
    assert model.outcome_probabilities(unseen, "F02")["F03"] < 0.02
    without = OnlineOperatorModel(space, slip_pool=0.0)
    without.update(square_23, "F02", "F02")
    alone = without.outcome_probabilities(square_23, "F02")["F03"]
    for _ in range(4):
        without.update(square_12, "F01", "F02")
    assert without.outcome_probabilities(square_23, "F02")["F03"] == pytest.approx(alone)
    # One slip seen in all: a few pseudo-counts, not a certainty.
    once = OnlineOperatorModel(space)
    once.update(square_12, "F01", "F02")
    once.update(square_23, "F02", "F02")
    assert once.outcome_probabilities(square_23, "F02")["F03"] < 0.1
