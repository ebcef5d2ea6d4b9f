"""What the project's policies, deciders, operators and body scripts offer beyond the basics
is declared (`hrc_drake.tasks.protocols`, `hrc_drake.cell.station.operator_body`), and each
part offers what the cell asks of it: a renamed method would leave the cell without it (the
robot would stop betting, a person's clicks would go unread, the slow operator would not
tire) and fails here."""

from __future__ import annotations

from hrc_drake.cell.run.evaluate import DeciderPolicy
from hrc_drake.cell.station.faults import SilentOperator
from hrc_drake.cell.station.operator_body import BoltingScript, Handed, KnowsWhenFree
from hrc_drake.hri.operator import ScriptedOperator
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.scenario.schema import BodyConfig
from hrc_drake.tasks.deciders import make_decider
from hrc_drake.tasks.interaction import DEFAULT_DELAYS, DelayedIndications
from hrc_drake.tasks.protocols import (
    AskedWithoutBlocking,
    Commits,
    DelaysIndications,
    HasOperatorModel,
    ObservesTasks,
    PredictsTasks,
    TiresAlongTheRun,
    TotalDelay,
)
from hrc_drake.tasks.solve import exact_policy


class _Clicker:
    """An operator asked without blocking, as the browser's is."""

    def poll(self, prompt):
        return None


def test_operators_offer_what_they_declare():
    scripted = ScriptedOperator({})
    assert not isinstance(scripted, AskedWithoutBlocking | DelaysIndications | TiresAlongTheRun)
    delayed = DelayedIndications(scripted, DEFAULT_DELAYS["pointer"])
    assert isinstance(delayed, DelaysIndications) and isinstance(delayed, TotalDelay)
    assert not isinstance(delayed, AskedWithoutBlocking)
    # What the wrapped operator offers passes through the interface's delay and the faults.
    assert isinstance(
        DelayedIndications(_Clicker(), DEFAULT_DELAYS["pointer"]), AskedWithoutBlocking
    )
    assert isinstance(SilentOperator(scripted, []), DelaysIndications)


def test_the_slow_population_tires_and_the_others_keep_their_pace(flange_space):
    """Every population model says how long it bolts; only `slow` slows down along the run."""
    slow, follows = (make_operator_model(n, flange_space) for n in ("slow", "follows"))
    assert isinstance(slow, TiresAlongTheRun) and isinstance(follows, TiresAlongTheRun)
    assert follows.bolt_scale(1) == follows.bolt_scale(10) == 1.0
    assert slow.bolt_scale(10) > slow.bolt_scale(1) >= 1.0


def test_deciders_and_policies_offer_what_the_supervisor_asks(flange_space, toy_costs):
    mpc = make_decider("mpc", flange_space, toy_costs)
    exact = make_decider("exact", flange_space, toy_costs)
    assert isinstance(mpc, HasOperatorModel) and isinstance(mpc, Commits)
    assert isinstance(exact, Commits) and not isinstance(exact, HasOperatorModel)
    as_policy = DeciderPolicy(mpc, flange_space)
    for protocol in (Commits, PredictsTasks, ObservesTasks):
        assert isinstance(as_policy, protocol), protocol
    # A policy file's policy only proposes: the robot bets on its proposal.
    plain = exact_policy(flange_space)
    assert not isinstance(plain, Commits | PredictsTasks | ObservesTasks)


def test_the_cells_body_script_says_its_hand_and_the_bolting_one_is_never_busy():
    script = BoltingScript(BodyConfig(left_handed=True))
    assert isinstance(script, Handed) and script.left_handed
    assert not isinstance(script, KnowsWhenFree)
