"""Policy files: versioned, checksummed, tied to their spec, written atomically."""

import copy
import json
import os

import pytest
import yaml

from hrc_drake.resources import default_assembly
from hrc_drake.tasks.graph import UnknownStateError, generate_states
from hrc_drake.tasks.policy import (
    PolicyFileError,
    load_policy,
    policy_from_choices,
    save_policy,
)
from hrc_drake.tasks.solve import solve_exact
from hrc_drake.tasks.spec import parse_spec


@pytest.fixture
def policy(flange_mdp):
    return policy_from_choices(flange_mdp, solve_exact(flange_mdp).choice, "exact", {"k": 1})


def test_round_trip(tmp_path, flange_space, policy):
    path = tmp_path / "p.json"
    save_policy(policy, path)
    loaded = load_policy(path, flange_space)
    assert loaded == policy
    assert loaded.next_task(("F3",)) == "S12"
    assert loaded.next_task(("F1", "S23", "F03")) is None
    assert [p.name for p in tmp_path.iterdir()] == ["p.json"]


def test_unknown_state_is_an_error(policy):
    with pytest.raises(UnknownStateError, match="not a state"):
        policy.next_task(("F2", "S23"))


def test_corrupted_files_are_clear_errors(tmp_path, flange_space, policy):
    path = tmp_path / "p.json"
    save_policy(policy, path)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(PolicyFileError, match="corrupted"):
        load_policy(path, flange_space)
    data = json.loads(text)
    data["entries"][0][1] = "S23"
    path.write_text(json.dumps(data))
    with pytest.raises(PolicyFileError, match="checksum"):
        load_policy(path, flange_space)
    data = json.loads(text)
    data["version"] = 99
    path.write_text(json.dumps(data))
    with pytest.raises(PolicyFileError, match="version"):
        load_policy(path, flange_space)
    with pytest.raises(PolicyFileError, match="not found"):
        load_policy(tmp_path / "none.json", flange_space)


def test_policy_for_another_spec_is_refused(tmp_path, policy):
    data = yaml.safe_load(default_assembly().read_text())
    other = copy.deepcopy(data)
    other["base"]["slots"] = 4
    other["state_names"] = {}
    other_space = generate_states(parse_spec(other, source="four.yaml"))
    path = tmp_path / "p.json"
    save_policy(policy, path)
    with pytest.raises(PolicyFileError, match=r"made for assembly 'flange'.*four\.yaml"):
        load_policy(path, other_space)


def test_failed_save_leaves_the_old_file(tmp_path, policy, monkeypatch):
    path = tmp_path / "p.json"
    save_policy(policy, path)
    before = path.read_text()

    def broken_replace(*_args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        save_policy(policy, path)
    assert path.read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["p.json"]
