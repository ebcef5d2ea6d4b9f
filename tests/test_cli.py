"""The `hrc-drake` command line on the task layer."""

import json

import pytest

from hrc_drake.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_states_json_is_table1(capsys):
    code, out, _ = run(capsys, "states", "--json")
    rows = json.loads(out)
    assert code == 0 and len(rows) == 20
    assert rows[8] == {
        "name": "9",
        "sequence": ["F1", "S23", "F02"],
        "configuration": ["F02", "F1", "S23"],
        "kind": "wrong",
        "tasks": ["undo"],
        "actions": ["disass"],
        "tasks_to_finish": 2,
    }


def test_policy_json_gives_next_sequence(capsys):
    code, out, _ = run(capsys, "policy", "--json")
    rows = {tuple(r["sequence"]): r for r in json.loads(out)}
    assert code == 0 and len(rows) == 20
    assert rows[("F3",)]["next"] == ["F3", "S12"]
    assert rows[("S12", "F02")]["next"] == ["S12"]
    assert rows[("F1", "S23", "F03")]["next"] is None
    assert rows[("F1", "S23", "F03")]["kind"] == "terminal"


def test_react_forces_4_then_8(capsys):
    code, out, _ = run(capsys, "react", "--operator", "1:F3,2:S12", "--json")
    assert code == 0
    assert json.loads(out)["states"] == [[], ["F3"], ["F3", "S12"], ["F3", "S12", "F01"]]


def test_solve_train_and_use_policy_files(capsys, tmp_path):
    exact, learned = tmp_path / "exact.json", tmp_path / "full.json"
    assert run(capsys, "solve", "--out", str(exact))[0] == 0
    assert run(capsys, "train", "--out", str(learned), "--schedule", "full", "--seed", "1")[0] == 0
    for path in (exact, learned):
        code, out, _ = run(
            capsys, "react", "--policy", str(path), "--operator", "1:S12,2:F02", "--json"
        )
        assert code == 0
        assert len(json.loads(out)["states"]) == 6  # 1 5 14 5 13 17


def test_table2_prints_three_columns(capsys):
    code, out, _ = run(capsys, "table2", "--json")
    rows = json.loads(out)
    assert code == 0 and len(rows) == 9
    assert all(r["policy"] == r["minimum_effort"] for r in rows)
    assert rows[3]["published"] == ["1", "4", "1", "2", "7", "10"]


def test_errors_are_reported_not_raised(capsys, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    code, _, err = run(capsys, "react", "--policy", str(bad))
    assert code == 2 and "corrupted" in err
    code, _, err = run(capsys, "react", "--operator", "1:F7")
    assert code == 2 and "not feasible" in err
    code, _, err = run(capsys, "states", "--assembly", str(tmp_path / "none.yaml"))
    assert code == 2 and "file not found" in err


@pytest.mark.parametrize("what", ["graph", "learning"])
def test_plots_are_written(capsys, tmp_path, what):
    out = tmp_path / f"{what}.png"
    assert run(capsys, "plot", what, "--out", str(out))[0] == 0
    assert out.read_bytes()[:4] == b"\x89PNG"
