"""Operator populations, the online operator model, deciders and `hrc-drake evaluate`.

A small hand-made cost table keeps these tests free of Drake planning.
"""

from __future__ import annotations

import json

import pytest

from hrc_drake.cli import main
from hrc_drake.evaluate import PLANNING_SECONDS, evaluate, simulate_run
from hrc_drake.evaluation_runs import Setup
from hrc_drake.hri.populations import (
    OPERATOR_MODELS,
    OperatorModel,
    make_operator_model,
    register_operator_model,
)
from hrc_drake.paths import UsageError
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import save_cost_table
from hrc_drake.tasks.deciders import make_decider
from hrc_drake.tasks.mpc import MpcDecider
from hrc_drake.tasks.operator_model import OnlineOperatorModel
from hrc_drake.tasks.tokens import UNDO

FLANGE = models_dir() / "assemblies" / "flange.yaml"


@pytest.fixture(scope="module")
def space(flange_space):
    return flange_space


@pytest.fixture(scope="module")
def costs(toy_costs):
    return toy_costs


def setup(space, costs, decider, model, **params):
    return Setup(space, costs, decider, model, params, seed=3)


def test_models_are_seeded_and_habitual_goes_first(space):
    a = make_operator_model("random", space, seed=5)
    b = make_operator_model("random", space, seed=5)
    assert [a(1, (), "F1") for _ in range(20)] == [b(1, (), "F1") for _ in range(20)]
    habit = make_operator_model("habitual", space)
    assert habit.order == "S23"
    assert habit(1, (), "F1") == "S23"
    assert habit(2, ("S23",), "F03") == "F03"
    assert make_operator_model("slow", space, growth="0.5").bolt_scale(3) == pytest.approx(2.0)


def test_online_model_learns_and_pools_over_proposals(space):
    model = OnlineOperatorModel(space)
    assert (
        max(model.outcome_probabilities((), "F1"), key=model.outcome_probabilities((), "F1").get)
        == "F1"
    )
    for _ in range(10):
        model.update((), "F1", "S23")
    p = model.outcome_probabilities((), "F1")
    assert p["S23"] > 0.6 and sum(p.values()) == pytest.approx(1.0)
    # A proposal never tried: the habit seen after F1 is expected there too.
    assert model.outcome_probabilities((), "F3")["S23"] > 0.5


def test_mpc_learns_a_habit_and_proposes_it(space, costs):
    # A habit of another part than the proposal: a robot that bets on its proposal swaps parts
    # (another seat of the same part would cost little: the re-target).
    decider = MpcDecider(space, costs)
    first = decider.propose(())
    assert first.startswith("F") and decider.commit((), first) == first
    runs = []
    for i in range(5):
        operator = make_operator_model("habitual", space, seed=i)  # the square on 2-3 first
        runs.append(simulate_run(space, costs, decider, operator))
    assert runs[0].swaps == 1  # it bet on a flange; the operator took the square
    learned = decider.propose(())
    assert learned.startswith("S") and decider.commit((), learned) == learned
    assert runs[-1].swaps == 0 and runs[-1].seconds < runs[0].seconds - 1.0
    assert decider.solve_seconds


def test_worst_case_has_the_shortest_longest_run(space, costs):
    worst = {}
    for name in ("exact", "time", "mpc", "worst-case"):
        report = evaluate(setup(space, costs, name, "mistake-prone", p="0.5"), runs=30)
        assert report["completion_rate"] == 1.0
        worst[name] = report["worst_time"]
    assert all(worst["worst-case"] <= w + 1e-9 for w in worst.values()), worst


@pytest.mark.parametrize("model", ["follows", "habitual", "change-of-mind", "slow"])
def test_planners_always_complete(space, costs, model):
    for name in ("exact", "time", "mpc", "worst-case"):
        report = evaluate(setup(space, costs, name, model), runs=8)
        assert report["completed"] == 8, (name, model)


def test_slow_operator_takes_longer(space, costs):
    fast = evaluate(setup(space, costs, "time", "follows"), runs=2)
    slow = evaluate(setup(space, costs, "time", "slow", growth="0.5"), runs=2)
    assert slow["mean_time"] > fast["mean_time"]
    assert slow["mean_tasks"] == fast["mean_tasks"]


def _simulated_figures(report):
    return {
        k: v
        for k, v in report.items()
        if not k.startswith("wall_") and k not in ("workers", "backend")
    }


def test_serial_and_parallel_give_the_same_report(space, costs):
    s = setup(space, costs, "mpc", "mistake-prone", p="0.4")
    serial = evaluate(s, runs=20)
    parallel = evaluate(s, runs=20, workers=2)
    assert _simulated_figures(serial) == _simulated_figures(parallel)
    assert serial["mean_undos"] > 0


def test_bad_names_and_params(space):
    with pytest.raises(ValueError, match=r"known models: .*habitual"):
        make_operator_model("lazy", space)
    with pytest.raises(ValueError, match="no parameter 'q'; its parameters: p"):
        make_operator_model("mistake-prone", space, q=0.1)
    with pytest.raises(ValueError, match="order='X9' is not a task"):
        make_operator_model("habitual", space, order="X9")
    with pytest.raises(UsageError, match="known deciders: paper-q"):
        make_decider("greedy", space, None)


def test_user_model_can_be_registered(space):
    class AlwaysUndo(OperatorModel):
        def __init__(self, space, seed=0, when=2):
            super().__init__(space, seed)
            self.when = int(when)

        def __call__(self, step, state, proposal):
            return UNDO if step == self.when else proposal

    register_operator_model("undo-once", AlwaysUndo)
    try:
        op = make_operator_model("undo-once", space, seed=1, when="1")
        assert op(1, ("F1",), "S23") == UNDO and op.when == 1
    finally:
        del OPERATOR_MODELS["undo-once"]


@pytest.fixture
def cost_file(tmp_path, costs):
    path = tmp_path / "costs.json"
    save_cost_table(costs, path)
    return path


def test_cli_evaluate_json_and_plot(tmp_path, cost_file, capsys):
    plot = tmp_path / "hist.png"
    args = ["evaluate", "--decider", "time", "--operator-model", "mistake-prone", "--runs", "10"]
    code = main(
        [*args, "--costs", str(cost_file), "--json", "--param", "p=0.5", "--plot", str(plot)]
    )
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["runs"] == 10 and 0.0 <= report["completion_rate"] <= 1.0
    for key in ("decider", "operator_model", "completed", "mean_time", "p95_time", "worst_time"):
        assert key in report
    # `time` has no operator model: it plans its proposal ahead, so the robot idles (planning)
    # exactly at the boundaries where the operator misplaced the part.
    ready = report["plan_ready_rate"]
    assert ready == pytest.approx(1 - report["mean_deviations"] / report["mean_tasks"], abs=1e-3)
    assert ready < 1 and report["mean_idle"] == pytest.approx(PLANNING_SECONDS * (1 - ready), 1e-3)
    assert plot.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--decider", "nope", "--operator-model", "follows"], "unknown decider 'nope'"),
        (["--decider", "mpc", "--operator-model", "lazy"], "unknown operator model 'lazy'"),
        (["--decider", "mpc", "--operator-model", "slow", "--param", "p=1"], "no parameter 'p'"),
        (["--decider", "mpc", "--operator-model", "slow", "--param", "p"], "KEY=VALUE"),
        (["--decider", "mpc", "--operator-model", "slow", "--mistake-prob", "0.3"], "--param"),
    ],
)
def test_cli_errors_are_one_line(cost_file, capsys, extra, message):
    assert main(["evaluate", *extra, "--costs", str(cost_file)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_scenario_names_an_operator_model(space):
    from hrc_drake.scenario.load import load_scenario

    text = "{operator: {model: habitual, seed: 4, params: {}}}"
    operator = load_scenario(scenario_text=text).operator_for(space)
    assert operator(1, (), "F1") == "S23"
    text = "{operator: {model: mistake-prone, params: {p: 1.0}}}"
    operator = load_scenario(scenario_text=text).operator_for(space)
    assert operator(1, ("F1", "S23"), "F03") == "F02"
