"""Assembly specs: the flange file, other assemblies as new files only, and bad specs."""

import copy
import re

import pytest
import yaml
from flange_data import TABLE1

from hrc_drake.resources import default_assembly
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.spec import load_spec, parse_spec


@pytest.fixture
def flange_data():
    return yaml.safe_load(default_assembly().read_text())


def test_flange_spec_reads_as_published(flange_data):
    spec = parse_spec(flange_data)
    assert spec.slots == 3
    assert [(p.symbol, p.count, p.footprint) for p in spec.parts] == [("F", 2, 1), ("S", 1, 2)]
    assert [t for t, _, _ in spec.placements()] == [
        "F1",
        "F2",
        "F3",
        "F01",
        "F02",
        "F03",
        "S12",
        "S23",
    ]


def test_spec_hash_ignores_labels_but_not_content(flange_data):
    base = parse_spec(flange_data).spec_hash
    relabelled = copy.deepcopy(flange_data)
    relabelled["state_names"] = {}
    relabelled["name"] = "renamed"
    assert parse_spec(relabelled).spec_hash == base
    wider = copy.deepcopy(flange_data)
    wider["base"]["slots"] = 4
    wider["state_names"] = {}
    assert parse_spec(wider).spec_hash != base


def test_four_slot_base_is_a_new_file_only(tmp_path, flange_data):
    data = copy.deepcopy(flange_data)
    data["base"]["slots"] = 4
    data["state_names"] = {}
    path = tmp_path / "four.yaml"
    path.write_text(yaml.safe_dump(data))
    space = generate_states(load_spec(path))
    assert space.n_states > len(TABLE1)
    assert "S34" in space.tokens and "F04" in space.tokens
    kinds = {space.configuration(s): StateKind(space.kind[s]) for s in range(space.n_states)}
    # The same min_gap rule, on a wider base: two oval flanges at least two slots apart.
    assert kinds[frozenset({"F1", "S34", "F03"})] == StateKind.TERMINAL
    assert kinds[frozenset({"F1", "S34", "F04"})] == StateKind.TERMINAL
    assert kinds[frozenset({"F2", "S34", "F03"})] == StateKind.WRONG
    assert kinds[frozenset({"F2"})] == StateKind.NORMAL  # S34 still fits beside it


def test_third_oval_flange_is_a_new_file_only(flange_data):
    data = copy.deepcopy(flange_data)
    data["base"]["slots"] = 5
    data["parts"]["F"]["count"] = 3
    data["mounts"][0]["count"] = 2
    data["state_names"] = {}
    space = generate_states(parse_spec(data))
    complete = [s for s in range(space.n_states) if len(space.configuration(s)) == 4]
    assert complete
    assert all(space.kind[s] in (StateKind.TERMINAL, StateKind.WRONG) for s in complete)


def test_explicit_correct_list_replaces_rules(flange_data):
    data = copy.deepcopy(flange_data)
    data["goal"] = {"correct": [["F1", "S23", "F03"]]}
    space = generate_states(parse_spec(data))
    terminal = [
        space.sequence(s) for s in range(space.n_states) if space.kind[s] == StateKind.TERMINAL
    ]
    assert sorted(terminal) == [("F1", "S23", "F03"), ("S23", "F03", "F1")]


def _broken(data, edit):
    data = copy.deepcopy(data)
    edit(data)
    return data


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["mounts"].append({"part": "X", "to": "base", "count": 1}), "unknown part"),
        (lambda d: d["parts"]["S"].update(footprint=4), "slot out of range"),
        (lambda d: d["goal"].update(correct=[["F1", "S23", "F04"]]), "slot out of range"),
        (
            lambda d: d.update(precedence={"before": [["F", "S"], ["S", "F"]]}),
            "contradictory precedence",
        ),
        (lambda d: d.update(precedence={"complete_first": ["F"]}), "contradictory precedence"),
        (lambda d: d.update(goal={}), "no goal"),
        (
            lambda d: d["goal"].update(min_gap=[{"parts": ["F", "F"], "slots": 3}]),
            "no complete configuration satisfies the goal",
        ),
        (lambda d: d["parts"]["F"].update(count=3), "make them agree"),
        (lambda d: d.update(colour="red"), "unknown key"),
        (lambda d: d["mounts"][1].update(to="F"), "no `host` entry"),
        (lambda d: d["base"].update(slots=0), "base.slots"),
        (lambda d: d["state_names"].update({"F2 S23": "99"}), "not a state"),
    ],
)
def test_bad_spec_names_key_and_problem(flange_data, edit, message):
    with pytest.raises(SpecError, match=message):
        generate_states(parse_spec(_broken(flange_data, edit), source="bad.yaml"))


def test_bad_yaml_and_missing_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: [unclosed\n")
    with pytest.raises(SpecError, match="bad YAML"):
        load_spec(path)
    with pytest.raises(SpecError, match="file not found"):
        load_spec(tmp_path / "missing.yaml")


# --- goal.correct: its form, entries that cannot be built, and min_gap AND correct -----------


@pytest.mark.parametrize(
    "correct",
    [
        ["F3", "S12", "F01"],  # a flat list
        "F3 S12 F01",  # a string
        [["F3", "S12", "F01"], "F1 S23 F03"],  # one entry a string
        [],
    ],
)
def test_correct_in_the_wrong_form_shows_the_expected_one(flange_data, correct):
    data = _broken(flange_data, lambda d: d["goal"].update(correct=correct))
    with pytest.raises(SpecError, match=r"goal\.correct.*correct: \[\[F3, S12, F01\]"):
        parse_spec(data, source="bad.yaml")


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        (["F1", "S23", "F07"], "unknown task 'F07'"),
        (["F1", "S23"], "has 2 parts but a complete assembly has 3"),
        (["F1", "F3", "S12"], "puts 2 'F' on base but the mounts put 1 there"),
        (["F2", "S23", "F01"], "F2 and S23 both occupy base slot 2"),
        (["F3", "S12", "F03"], "F03 sits on 'S' over slot 3 but no 'S' covers that slot"),
        (["F1", "S23", "F03", "F03"], "lists 'F03' twice"),
    ],
)
def test_correct_entry_that_cannot_be_built_is_named(flange_data, entry, message):
    data = _broken(flange_data, lambda d: d["goal"].update(correct=[["F1", "S23", "F03"], entry]))
    with pytest.raises(SpecError, match=r"goal\.correct\[1\]: .*" + re.escape(message)):
        parse_spec(data, source="bad.yaml")


def test_correct_entry_no_sequence_reaches_is_named(flange_data):
    # Every oval flange before the square: the one that goes on the square never can.
    def edit(d):
        d["precedence"] = {"before": [["F", "S"]]}
        d["goal"]["correct"] = [["F1", "S23", "F03"]]

    with pytest.raises(SpecError, match=r"goal\.correct\[0\].*cannot be built by any sequence"):
        generate_states(parse_spec(_broken(flange_data, edit), source="bad.yaml"))


def test_min_gap_and_correct_combine_with_and(flange_data):
    # Both given: only the listed configurations that also keep the gap are terminal.
    data = _broken(flange_data, lambda d: d["goal"].update(correct=[["F1", "S23", "F03"]]))
    space = generate_states(parse_spec(data))
    terminal = {
        space.configuration(s) for s in range(space.n_states) if space.kind[s] == StateKind.TERMINAL
    }
    assert terminal == {frozenset({"F1", "S23", "F03"})}
    assert space.state_kind(space.index(("F3", "S12", "F01"))) == StateKind.WRONG
    # A listed configuration that breaks the gap could never be correct: refused, rule named.
    data = _broken(flange_data, lambda d: d["goal"].update(correct=[["F1", "S23", "F02"]]))
    with pytest.raises(SpecError, match=r"goal\.correct\[0\].*breaks goal\.min_gap\[0\].*AND"):
        parse_spec(data, source="bad.yaml")


# --- state_names ------------------------------------------------------------------------------


def test_state_names_must_label_every_state(flange_data):
    wider = _broken(flange_data, lambda d: d["base"].update(slots=4))
    with pytest.raises(SpecError, match="state_names: labels 20 of the 44 generated states"):
        generate_states(parse_spec(wider, source="four.yaml"))
    fewer = _broken(flange_data, lambda d: d["state_names"].pop("S23 F03 F1"))
    with pytest.raises(SpecError, match="state_names: labels 19 of the 20 generated states"):
        generate_states(parse_spec(fewer, source="bad.yaml"))


def test_state_names_that_are_not_states_are_all_named(flange_data):
    def edit(d):
        d["state_names"]["F2 S23"] = "21"
        d["state_names"]["S12 F03"] = "22"

    with pytest.raises(SpecError, match=r"'F2 S23', 'S12 F03' are not a state"):
        generate_states(parse_spec(_broken(flange_data, edit), source="bad.yaml"))


def test_state_names_must_differ_and_tolerate_spacing(flange_data):
    clash = _broken(flange_data, lambda d: d["state_names"].update({"S23 F03 F1": "10"}))
    with pytest.raises(SpecError, match=r"label\(s\) \['10'\] given to more than one state"):
        generate_states(parse_spec(clash, source="bad.yaml"))

    def respace(d):
        d["state_names"]["  F1   S23 "] = d["state_names"].pop("F1 S23")

    space = generate_states(parse_spec(_broken(flange_data, respace)))
    assert space.name(space.index(("F1", "S23"))) == "7"


def test_state_kind_keys_are_snake_case():
    assert StateKind.DEAD_END.key == "dead_end" and StateKind.DEAD_END.label == "dead end"
    assert [k.key for k in StateKind] == ["start", "normal", "terminal", "wrong", "dead_end"]
