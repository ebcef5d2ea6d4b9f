"""The robot moves on its prediction, at task level: the interaction timeline (wait, anticipate,
a right bet, a wrong seat, a wrong part), the deciders' bets, operator profiles and the flags.

The hand-made cost table of `conftest.toy_costs` (carry from 2.5 s to 4 s, re-target 0.8 s,
swap 4 s) and fixed delays keep the expected seconds exact.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import TOY_CARRY

from hrc_drake.cli import main
from hrc_drake.evaluate import evaluate, simulate_run
from hrc_drake.evaluation_runs import Setup
from hrc_drake.hri.operator import ScriptedOperator
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.paths import UsageError
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.tasks.costs import (
    CostTableError,
    load_cost_table,
    save_cost_table,
    table_from_seconds,
)
from hrc_drake.tasks.decide import run_decisions
from hrc_drake.tasks.deciders import make_decider
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import (
    DEFAULT_DELAYS,
    Bet,
    DelayedIndications,
    IndicationDelay,
    Interaction,
    InteractionCosts,
    InteractionError,
    bet_kind,
    extra_seconds,
    make_interaction,
)
from hrc_drake.tasks.mpc import MpcDecider
from hrc_drake.tasks.profile import (
    ProfileError,
    learn,
    load_or_new_profile,
    load_profile,
    new_profile,
    save_profile,
    update_profile,
)
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import parse_spec

RETARGET, SWAP = 0.8, 4.0  # the toy table's planned bets
START, END = TOY_CARRY


@pytest.fixture(scope="module")
def space(flange_space):
    return flange_space


@pytest.fixture(scope="module")
def costs(toy_costs):
    return toy_costs


def fixed(mode: str, seconds: float) -> Interaction:
    return make_interaction(mode, "pointer", IndicationDelay("fixed", seconds, 0.0))


def run(space, costs, decider_name, script, interaction):
    """One scripted run of a decider: the run and the tasks the operator performed."""
    decider = make_decider(decider_name, space, costs, interaction=interaction)
    operator = ScriptedOperator(script)
    timeline = InteractionCosts(space, costs, interaction)
    result = simulate_run(space, costs, decider, operator, timeline)
    _, decisions = run_decisions(space, exact_policy(space), ScriptedOperator(script))
    return result, decisions


def task_seconds(costs, decisions) -> float:
    return sum(costs.seconds(d.state, d.performed) for d in decisions)


# --- the timeline --------------------------------------------------------------------------


@pytest.mark.parametrize("delay", [3.0, 5.0])
def test_wait_spends_every_delay_and_anticipate_saves_it(space, costs, delay):
    """`exact` with an operator who follows: F1, S23, F03. Waiting adds the delay at every
    boundary; a right bet adds only the part of the delay past the carry's end (4 s)."""
    waited, decisions = run(space, costs, "exact", {}, fixed("wait", delay))
    assert [d.performed for d in decisions] == ["F1", "S23", "F03"]
    assert waited.seconds == pytest.approx(task_seconds(costs, decisions) + 3 * delay)
    assert (waited.commits, waited.indication_wait) == (0, pytest.approx(3 * delay))
    moved, _ = run(space, costs, "exact", {}, fixed("anticipate", delay))
    late = max(0.0, delay - END)
    assert moved.seconds == pytest.approx(task_seconds(costs, decisions) + 3 * late)
    assert (moved.commits, moved.retargets, moved.swaps) == (3, 0, 0)
    assert moved.indication_delay == pytest.approx(3 * delay)


@pytest.mark.parametrize(
    ("delay", "extra"),
    [
        (2.0, 0.0),  # still picking the part: the carry goes to the right seat
        (3.0, RETARGET * (3.0 - START) / (END - START)),  # part of the way to the wrong seat
        (5.0, RETARGET + (5.0 - END)),  # at the wrong seat's pre-place, then waited there
    ],
)
def test_a_wrong_seat_costs_the_retarget(space, costs, delay, extra):
    """The operator puts the flange on 3 where the robot proposed and carries it to 1."""
    result, decisions = run(space, costs, "exact", {1: "F3"}, fixed("anticipate", delay))
    assert (decisions[0].proposed, decisions[0].performed) == ("F1", "F3")
    assert bet_kind(space, "F1", "F3") == Bet.RETARGET
    right = 2 * max(0.0, delay - END)  # the two later bets are right
    assert result.seconds == pytest.approx(task_seconds(costs, decisions) + extra + right)
    assert (result.retargets, result.swaps, result.deviations) == (1, 0, 1)


@pytest.mark.parametrize(
    ("delay", "extra"),
    [
        (1.0, SWAP * 1.0 / START),  # on the way to the flange: part of the detour
        (3.0, SWAP + 2 * (3.0 - START)),  # the flange lifted and carried: back, and swap
        (5.0, SWAP + 2 * (END - START) + (5.0 - END)),
    ],
)
def test_a_wrong_part_costs_the_swap(space, costs, delay, extra):
    """The operator takes the square where the robot proposed (and picked) a flange."""
    result, decisions = run(space, costs, "exact", {1: "S12"}, fixed("anticipate", delay))
    assert decisions[0].proposed == "F1" and decisions[0].performed == "S12"
    assert bet_kind(space, "F1", "S12") == Bet.SWAP
    right = (len(decisions) - 1) * max(0.0, delay - END)
    assert result.seconds == pytest.approx(task_seconds(costs, decisions) + extra + right)
    assert (result.retargets, result.swaps) == (0, 1)


def test_an_undo_is_a_swap_and_the_robot_waits_for_an_undo(space, costs):
    delay = 3.0
    # Step 2: the operator takes F1 back where the robot proposed the square.
    result, decisions = run(space, costs, "exact", {2: "undo"}, fixed("anticipate", delay))
    assert [d.performed for d in decisions][:2] == ["F1", "undo"]
    assert bet_kind(space, "S23", "undo") == Bet.SWAP
    extra = SWAP + 2 * (delay - START)
    assert result.seconds == pytest.approx(task_seconds(costs, decisions) + extra)
    assert result.swaps == 1 and result.commits == len(decisions)
    timeline = InteractionCosts(space, costs, fixed("anticipate", delay))
    # A decider never bets on an undo: the robot waits for the indication.
    assert timeline.best_bet(("F1",), {"undo": 1.0}, "undo") == (None, delay)


def test_extra_seconds_is_the_documented_model():
    d = np.array([0.0, START, (START + END) / 2, END, END + 1.0])
    assert list(extra_seconds(Bet.RIGHT, d, START, END, 0.0)) == [0, 0, 0, 0, 1.0]
    assert list(extra_seconds(Bet.RETARGET, d, START, END, 0.8)) == pytest.approx(
        [0, 0, 0.4, 0.8, 1.8]
    )
    assert list(extra_seconds(Bet.SWAP, d, START, END, 4.0)) == pytest.approx(
        [0, 4.0, 5.5, 7.0, 8.0]
    )


def test_same_seed_same_result_and_delays_drawn_per_run(space, costs):
    setup = Setup(space, costs, "mpc", "mistake-prone", {"p": "0.4"}, 11)
    first, again = evaluate(setup, 30), evaluate(setup, 30)
    keys = [k for k in first if not k.startswith("wall_")]
    assert {k: first[k] for k in keys} == {k: again[k] for k in keys}
    assert len(set(first["times"])) > 10  # delays and mistakes differ from run to run
    assert first["interaction"] == "anticipate" and first["interface"] == "pointer"


# --- the deciders' bets ------------------------------------------------------------------


def test_deciders_commit_by_expected_seconds(space, costs):
    interaction = make_interaction()
    # No operator model: always the proposal (a placement).
    for name in ("exact", "paper-q"):
        decider = make_decider(name, space, costs, interaction=interaction)
        assert decider.commit((), decider.propose(())) == decider.propose(())
    # `time`: 5 % misplacements of the flange on the square cost a cheap re-target: commit.
    time_decider = make_decider("time", space, costs, interaction=interaction)
    assert time_decider.commit(("S12",), "F01") == "F01"
    # mpc, after an operator who took the square (on 1-2 or 2-3) instead of its flange: betting
    # on the flange again would likely cost a swap, more than waiting for the indication.
    mpc = MpcDecider(space, costs, interaction)
    first = mpc.propose(())
    assert first.startswith("F") and mpc.commit((), first) == first
    for answer in ["S12", "S23"] * 6:
        mpc.observe((), first, answer)
    probabilities = mpc.model.outcome_probabilities((), first)
    assert max(probabilities.values()) < 0.5 and probabilities[first] > 0.2
    assert mpc.commit((), first) is None
    # Betting on the square instead is cheap either way (S12 -> S23 is a re-target).
    assert mpc.commit((), "S12") == "S12"
    # In wait mode nobody commits.
    for name in ("exact", "time", "mpc", "worst-case"):
        decider = make_decider(name, space, costs, interaction=make_interaction("wait"))
        assert decider.commit((), decider.propose(())) is None


def test_worst_case_commits_when_the_worst_answer_is_a_cheap_retarget(space, costs):
    decider = make_decider("worst-case", space, costs, interaction=make_interaction())
    assert decider.commit(("S12",), "F01") == "F01"  # the worst answer: F02, a re-target
    report = evaluate(Setup(space, costs, "worst-case", "mistake-prone", {"p": "0.5"}, 3), 20)
    assert report["completed"] == 20 and report["commit_rate"] > 0.5


def test_keep_model_learns_one_operator_across_runs(space, costs):
    """A habit of another part than the first proposal: reset every run, mpc swaps parts every
    time; kept across runs, it learns to propose (and bet on) the habit."""
    reset = evaluate(Setup(space, costs, "mpc", "habitual", {}, 5), 10)
    kept = evaluate(Setup(space, costs, "mpc", "habitual", {}, 5, keep_model=True), 10)
    assert reset["mean_swaps"] == 1.0 and kept["keep_model"] is True
    assert kept["mean_swaps"] <= 0.3 and kept["mean_time"] < reset["mean_time"] - 2.0
    with pytest.raises(UsageError, match=r"--keep-model.*drop --workers"):
        evaluate(Setup(space, costs, "mpc", "habitual", {}, 5, keep_model=True), 4, workers=2)


# --- operator profiles ---------------------------------------------------------------------


def _learned_profile(space, runs: int = 6):
    """A profile of a habitual operator (the square on 2-3 first, whatever is proposed)."""
    profile = new_profile(space)
    for i in range(runs):
        operator = make_operator_model("habitual", space, seed=i)
        _, decisions = run_decisions(space, exact_policy(space), operator)
        learn(profile, decisions)
    return profile


def test_a_kept_profile_changes_the_next_runs_commitment(tmp_path, space, costs):
    path = tmp_path / "operator.json"
    save_profile(_learned_profile(space), path)
    loaded = load_profile(path, space)
    assert loaded.assemblies == 6
    fresh = make_decider("mpc", space, costs)
    known = make_decider("mpc", space, costs, model=loaded.model)
    first, learned = fresh.propose(()), known.propose(())
    assert fresh.commit((), first) == first and first.startswith("F")
    assert learned.startswith("S") and known.commit((), learned) == learned
    # The profile survives a reset (a new run by the same person), and evaluate takes it.
    known.reset()
    assert known.propose(()) == learned
    report = evaluate(Setup(space, costs, "mpc", "habitual", {}, 0, model=loaded.model), 4)
    assert report["mean_swaps"] == 0.0


def test_profile_files_are_checked(tmp_path, space):
    path = tmp_path / "operator.json"
    assert load_or_new_profile(path, space).assemblies == 0  # no file yet: a new profile
    save_profile(_learned_profile(space, 2), path)
    data = json.loads(path.read_text())
    assert data["format"] == "hrc_drake.operator_profile" and data["version"] == 1
    assert data["observations"] and "checksum" in data
    with pytest.raises(ProfileError, match="checksum mismatch"):
        path.write_text(path.read_text().replace('"assemblies": 2', '"assemblies": 3'))
        load_profile(path, space)
    save_profile(_learned_profile(space, 2), path)
    spec = json.loads(json.dumps(_spec_data()))
    spec["parts"]["F"]["bolt_time"] = 7.5
    other = generate_states(parse_spec(spec, "slow-bolting.yaml"))
    with pytest.raises(ProfileError, match=r"made for assembly 'flange'.*slow-bolting") as err:
        load_profile(path, other)
    assert "\n" not in str(err.value) and "--operator-profile" in str(err.value)
    path.write_text("{not json")
    with pytest.raises(ProfileError, match="not JSON"):
        load_profile(path, space)


def test_concurrent_profile_updates_keep_both_sessions(tmp_path, space, monkeypatch):
    """Two runs ending at once with one profile: each update reads, learns and writes under the
    file's lock, so both sessions are counted (unlocked, both would read the same file and the
    later write would drop the other's session)."""
    import threading
    import time

    import hrc_drake.tasks.profile as profile_module

    path = tmp_path / "operator.json"
    save_profile(_learned_profile(space, 1), path)
    _, decisions = run_decisions(space, exact_policy(space), ScriptedOperator({1: "F3"}))
    learn_now = profile_module.learn

    def slow_learn(profile, tasks):
        time.sleep(0.3)  # long enough that the other update reads before this one writes
        return learn_now(profile, tasks)

    monkeypatch.setattr(profile_module, "learn", slow_learn)
    errors = []

    def run():
        try:
            update_profile(path, space, decisions)
        except Exception as err:  # pragma: no cover - reported by the assertion below
            errors.append(err)

    threads = [threading.Thread(target=run) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    saved = load_profile(path, space)
    assert saved.assemblies == 3
    assert saved.model.observations((), "F1").get("F3") == 2.0
    assert (tmp_path / "operator.json.lock").exists()


def _spec_data():
    import yaml

    from hrc_drake.resources import default_assembly

    return yaml.safe_load(default_assembly().read_text())


# --- interaction data, scenario keys and flags ----------------------------------------------


def test_interaction_values_and_defaults():
    assert make_interaction() == Interaction("anticipate", "pointer", DEFAULT_DELAYS["pointer"])
    assert make_interaction("wait", "touch").delay == DEFAULT_DELAYS["touch"]
    for mode, interface, match in [("later", None, "unknown interaction mode 'later'"),
                                   (None, "voice", "unknown interface 'voice'")]:  # fmt: skip
        with pytest.raises(InteractionError, match=match):
            make_interaction(mode, interface)
    with pytest.raises(InteractionError, match=r"delay\.median"):
        make_interaction(delay=IndicationDelay("lognormal", -1.0, 0.3))
    delay = IndicationDelay("lognormal", 2.0, 0.3)
    assert delay.mean == pytest.approx(2.0 * np.exp(0.045))
    assert np.mean(delay.nodes()) == pytest.approx(delay.mean, rel=2e-3)
    rng = np.random.default_rng(0)
    draws = [delay.sample(rng) for _ in range(4000)]
    assert np.median(draws) == pytest.approx(2.0, rel=0.03) and min(draws) > 0


def test_scenario_interaction_section_is_typed_and_checked(space):
    scenario = load_scenario(
        scenario_text="{interaction: {mode: wait, interface: touch, delay: {median: 1.2}}}"
    )
    interaction = scenario.interaction_model()
    assert (interaction.mode, interaction.interface, interaction.delay.median) == (
        "wait",
        "touch",
        1.2,
    )
    assert load_scenario().interaction_model() == make_interaction()
    for text, key in [
        ("{interaction: {mode: later}}", "interaction.mode: unknown mode 'later'"),
        ("{interaction: {interface: voice}}", "interaction.interface: unknown interface"),
        ("{interaction: {delay: {median: -1}}}", "interaction.delay.median"),
        ("{interaction: {delay: {sigma: -0.1}}}", "interaction.delay.sigma"),
        ("{interaction: {delay: {distribution: gamma}}}", "interaction.delay.distribution"),
        ("{interaction: {delay: {median: fast}}}", "median"),
        ("{interaction: {mood: calm}}", "mood"),
    ]:
        with pytest.raises(ScenarioError, match=key):
            load_scenario(scenario_text=text)
    # The scenario's operator gives its indications after seeded delays (the station waits).
    operator = load_scenario(scenario_text="{operator: {seed: 3}}").operator_for(space)
    again = load_scenario(scenario_text="{operator: {seed: 3}}").operator_for(space)
    assert isinstance(operator, DelayedIndications) and operator(1, (), "F1") == "F1"
    delays = [operator.indication_delay(k) for k in (1, 2, 3)]
    assert delays == [again.indication_delay(k) for k in (1, 2, 3)]
    assert operator.indication_delay(1) == delays[0] and len(set(delays)) == 3


@pytest.fixture
def cost_file(tmp_path, costs):
    path = tmp_path / "costs.json"
    save_cost_table(costs, path)
    return path


def _one_line_error(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err


def test_evaluate_reports_the_interaction(cost_file, capsys):
    args = ["evaluate", "--decider", "mpc", "--operator-model", "mistake-prone", "--json"]
    assert main([*args, "--runs", "20", "--costs", str(cost_file), "--param", "p=0.5"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["interaction"] == "anticipate" and report["interface"] == "pointer"
    assert 0.5 < report["commit_rate"] <= 1.0 and report["mean_retargets"] > 0
    assert report["mean_swaps"] >= 0 and report["indication_delay"]["median"] == 2.0
    more = ["--interaction", "wait", "--interface", "gesture", "--runs", "20"]
    assert main([*args, *more, "--costs", str(cost_file), "--param", "p=0.5"]) == 0
    waited = json.loads(capsys.readouterr().out)
    assert waited["interaction"] == "wait" and waited["commit_rate"] == 0.0
    assert waited["mean_retargets"] == waited["mean_swaps"] == 0.0
    assert waited["mean_indication_wait"] == waited["mean_indication_delay"] > 0


def test_bad_interaction_inputs_are_one_line_errors(tmp_path, cost_file, capsys, monkeypatch):
    evaluate_args = ["evaluate", "--decider", "mpc", "--operator-model", "follows"]
    _one_line_error(
        capsys, [*evaluate_args, "--interaction", "later"], "--interaction: unknown interaction"
    )
    _one_line_error(capsys, [*evaluate_args, "--interface", "voice"], "unknown interface 'voice'")
    _one_line_error(
        capsys,
        [*evaluate_args, "--keep-model", "--workers", "2", "--costs", str(cost_file)],
        "--keep-model",
    )
    _one_line_error(
        capsys, ["costs", "--out", str(tmp_path / "c.json"), "--interface", "voice"], "voice"
    )
    # simulate: refused before anything is built or simulated.
    import hrc_drake.cli.simulate as command

    def no_run(*args, **kwargs):
        raise AssertionError("the run started")

    monkeypatch.setattr(command, "_run", no_run)
    _one_line_error(capsys, ["simulate", "--interaction", "later"], "unknown interaction mode")
    _one_line_error(capsys, ["simulate", "--interface", "voice"], "unknown interface")
    _one_line_error(
        capsys,
        ["simulate", "--scenario-text", "{interaction: {delay: {median: -2}}}"],
        "interaction.delay.median",
    )
    profile = tmp_path / "profile.json"
    profile.write_text("{not json")
    _one_line_error(capsys, ["simulate", "--operator-profile", str(profile)], "not JSON")
    other = tmp_path / "other.json"
    four = generate_states(load_spec_file("four-slot.yaml"))
    save_profile(new_profile(four), other)
    _one_line_error(capsys, ["simulate", "--operator-profile", str(other)], "made for assembly")


def load_spec_file(name: str):
    from hrc_drake.resources import models_dir
    from hrc_drake.tasks.spec import load_spec

    return load_spec(models_dir() / "assemblies" / name)


def test_tables_without_bets_serve_wait_only(tmp_path, space, costs, capsys):
    plain = table_from_seconds(space, {k: v.seconds for k, v in costs.entries.items()})
    path = tmp_path / "plain.json"
    save_cost_table(plain, path)
    with pytest.raises(CostTableError, match=r"re-target and swap times.*--interaction wait"):
        InteractionCosts(space, load_cost_table(path, space), make_interaction())
    args = ["evaluate", "--decider", "time", "--operator-model", "follows", "--costs", str(path)]
    _one_line_error(capsys, args, "--interaction wait")
    assert main([*args, "--interaction", "wait", "--runs", "3"]) == 0
    # A table of the first format (no milestones, no bets) is refused with the fix.
    data = json.loads(path.read_text())
    data["version"] = 1
    path.write_text(json.dumps(data))
    with pytest.raises(CostTableError, match="version 1 \\(without the re-target and swap"):
        load_cost_table(path, space)


def test_bets_round_trip_and_incomplete_bets_are_refused(tmp_path, space, costs):
    path = tmp_path / "costs.json"
    save_cost_table(costs, path)
    loaded = load_cost_table(path, space)
    assert loaded.bets == costs.bets and loaded.entries == costs.entries
    assert loaded.cost((), "F1").carry_start == START
    data = json.loads(path.read_text())
    assert {"state", "committed", "indicated", "seconds"} == set(data["bets"][0])
    bets = dict(costs.bets)
    bets.pop(((), "F1", "F3"))
    from dataclasses import replace

    save_cost_table(replace(costs, bets=bets), path)
    with pytest.raises(CostTableError, match="no bet on 'F1' -> 'F3' in \\[\\]"):
        load_cost_table(path, space)


# --- the cell: the simulated operator indicates after the delay ------------------------------


def test_the_simulated_operator_indicates_after_the_delay():
    pytest.importorskip("pydrake")
    from pydrake.common.value import AbstractValue
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantValueSource

    from hrc_drake.cell.ports import CellConfiguration
    from hrc_drake.cell.station.sim_operator import SimulatedOperator
    from hrc_drake.hri.messages import Prompt, PromptKind

    def indication_after(operator, seconds: float):
        builder = DiagramBuilder()
        person = builder.AddSystem(SimulatedOperator(operator, 1.0, 0.02))
        prompt = Prompt(1, PromptKind.CHOOSE, (), "F1")
        for port, value in (("hri.prompt", prompt), ("configuration", CellConfiguration())):
            source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(value)))
            builder.Connect(source.get_output_port(), person.GetInputPort(port))
        diagram = builder.Build()
        simulator = Simulator(diagram)
        simulator.AdvanceTo(seconds)
        context = person.GetMyContextFromRoot(simulator.get_context())
        return person.GetOutputPort("hri.indication").Eval(context)

    delayed = DelayedIndications(ScriptedOperator({1: "F3"}), IndicationDelay("fixed", 0.5, 0.0))
    assert indication_after(delayed, 0.45).task is None  # not yet
    given = indication_after(delayed, 0.6)
    assert given.step == 1 and given.task == "F3" and given.time == pytest.approx(0.5, abs=0.021)
    at_once = indication_after(ScriptedOperator({1: "F3"}), 0.05)  # no delay: a person clicking
    assert at_once.task == "F3" and at_once.time == pytest.approx(0.0)


@pytest.mark.slow
def test_simulate_learns_and_saves_the_operator_profile(tmp_path, capsys, space):
    """`simulate --operator-profile FILE`: a new profile when FILE is missing, learned from
    what the cell observed and saved; the next run loads it and adds to it."""
    path = tmp_path / "operator.json"
    args = ["simulate", "--scenario", "row4-forces-4", "--lean", "--json"]
    more = ["--scenario-text", "{body: {enabled: false}}", "--operator-profile", str(path)]
    assert main([*args, *more, "--interface", "gesture"]) == 0
    data = json.loads(capsys.readouterr().out)
    profile = load_profile(path, space)
    assert profile.assemblies == 1
    # The cell observed F3 where the robot proposed F1 (the row's script), then it followed.
    assert profile.model.observations((), "F1") == {"F3": 1.0}
    assert [s["observed"] for s in data["steps"]] == ["F3", "S12", "F01"]
    assert main([*args, *more, "--interaction", "wait"]) == 0
    capsys.readouterr()
    assert load_profile(path, space).model.observations((), "F1") == {"F3": 2.0}


def test_a_cell_evaluation_takes_the_scenarios_interaction_under_the_flags():
    from argparse import Namespace

    from hrc_drake.cli.evaluate import cell_interaction

    scenario = load_scenario(
        scenario_text="{interaction: {mode: wait, interface: touch, delay: {median: 1.0}}}"
    )
    kept = cell_interaction(Namespace(interaction=None, interface=None), scenario)
    assert (kept.mode, kept.interface, kept.delay.median) == ("wait", "touch", 1.0)
    flagged = cell_interaction(Namespace(interaction="anticipate", interface="gesture"), scenario)
    assert (flagged.mode, flagged.interface, flagged.delay.median) == ("anticipate", "gesture", 1.0)
    plain = cell_interaction(Namespace(interaction=None, interface="gesture"), load_scenario())
    assert plain.delay == DEFAULT_DELAYS["gesture"]
    with pytest.raises(UsageError, match="unknown interface 'voice'"):
        cell_interaction(Namespace(interaction=None, interface="voice"), scenario)
