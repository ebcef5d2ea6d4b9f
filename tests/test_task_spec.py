"""Assembly specs: the flange file, other assemblies as new files only, and bad specs."""

import copy

import pytest
import yaml
from flange_data import TABLE1

from hrc_drake.resources import default_assembly
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.spec import SpecError, load_spec, parse_spec


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
