"""Operators: scripts, stochastic deviations, and scenario files."""

import pytest

from hrc_drake.hri.operator import (
    OperatorScriptError,
    ScriptedOperator,
    StochasticOperator,
    parse_operator_script,
)
from hrc_drake.scenario.load import load_scenario, table2_scenarios
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.tasks.decide import run_decisions
from hrc_drake.tasks.graph import StateKind
from hrc_drake.tasks.solve import exact_policy


def test_script_parsing():
    assert parse_operator_script("1:F3, 2:S12") == {1: "F3", 2: "S12"}
    assert parse_operator_script("") == {}
    for bad in ("1F3", "0:F1", "1:F1,1:F2", "a:F1", "2:"):
        with pytest.raises(OperatorScriptError):
            parse_operator_script(bad)


def test_scripted_operator_overrides_only_its_steps():
    op = ScriptedOperator({2: "S12"})
    assert op(1, (), "F1") == "F1"
    assert op(2, ("F3",), "undo") == "S12"


def test_stochastic_operator_always_ends_terminal_and_is_seeded(flange_space):
    policy = exact_policy(flange_space)
    runs = []
    for seed in range(30):
        op = StochasticOperator(flange_space, override_prob=0.3, mistake_prob=0.5, seed=seed)
        states, _decisions = run_decisions(flange_space, policy, op, max_steps=200)
        assert flange_space.kind[flange_space.index(states[-1])] == StateKind.TERMINAL
        runs.append(states)
    assert len({tuple(r) for r in runs}) > 3  # the operator really deviates
    again = run_decisions(
        flange_space, policy, StochasticOperator(flange_space, 0.3, 0.5, seed=0), max_steps=200
    )[0]
    assert again == runs[0]


def test_mistakes_only_where_the_spec_allows(flange_space):
    op = StochasticOperator(flange_space, 0.0, 1.0, seed=0)
    assert op.alternatives(("F1", "S23"), "F03") == ["F02"]
    assert op.alternatives((), "F1") == []  # placements on the base are not confusable
    assert op(1, ("F1", "S23"), "F03") == "F02"


def test_table2_scenarios_are_the_nine_rows():
    rows = table2_scenarios()
    assert [r.table2_row for r in rows] == list(range(1, 10))
    assert rows[7].script == {1: "F3", 2: "S12"}
    assert rows[7].minimum_effort == ("1", "4", "8", "11")


def test_bad_scenarios(tmp_path):
    with pytest.raises(ScenarioError, match="not found; known scenarios"):
        load_scenario("no-such-row")
    path = tmp_path / "s.yaml"
    path.write_text("name: x\noperator: {script: '1:F3'}\n")
    with pytest.raises(ScenarioError, match=r"operator\.script: unknown key"):
        load_scenario(path)
    path.write_text("name: x\nspeed: 3\n")
    with pytest.raises(ScenarioError, match="speed: unknown key"):
        load_scenario(path)
    path.write_text("name: x\nexpected: {minimum_efort: ['1']}\n")
    with pytest.raises(ScenarioError, match=r"expected\.minimum_efort: unknown key"):
        load_scenario(path)
    path.write_text("name: x\noperator: {seed: 3.7}\n")
    with pytest.raises(ScenarioError, match=r"operator\.seed: expected a whole number, got 3\.7"):
        load_scenario(path)
    path.write_text("name: x\noperator: {mistake_prob: 1.5}\n")
    with pytest.raises(ScenarioError, match=r"within \[0, 1\], got 1\.5"):
        load_scenario(path)
    path.write_text("name: x\noperator: {deviations: [{step: 0, task: F3}]}\n")
    with pytest.raises(ScenarioError, match="steps count from 1"):
        load_scenario(path)
