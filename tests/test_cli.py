"""The `hrc-drake` command line on the task layer."""

import dataclasses
import json
import os
import subprocess
import sys
import types

import pytest

from hrc_drake.cli import main
from hrc_drake.cli import tasks as task_commands
from hrc_drake.paths import UsageError, check_output_path
from hrc_drake.tasks.decide import StepLimitError, run_decisions
from hrc_drake.tasks.policy import save_policy
from hrc_drake.tasks.solve import exact_policy


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


# --- Seams a new user hit (issue 9, item 7) ---------------------------------------------------


def _one_line_error(code, err, command, *words):
    assert code == 2
    assert err.startswith(f"hrc-drake {command}: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, (word, err)


@pytest.mark.parametrize(
    "argv",
    [
        ["solve"],
        ["train", "--schedule", "paper"],
        ["plot", "learning"],
    ],
)
def test_output_path_is_checked_before_any_work(capsys, tmp_path, argv):
    (tmp_path / "a_file").write_text("")
    cases = [
        (tmp_path, "is a directory"),
        (tmp_path / "missing" / "out.png", "does not exist"),
        (tmp_path / "a_file" / "out.png", "is not a folder"),
    ]
    for out, words in cases:
        code, stdout, err = run(capsys, *argv, "--out", str(out))
        _one_line_error(code, err, argv[0], "--out", words)
        assert stdout == ""  # no training, no progress, nothing written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_check_output_path_accepts_a_writable_file_name(tmp_path):
    assert check_output_path(tmp_path / "fig.PDF", "--out", suffixes=(".png", ".pdf")) == (
        tmp_path / "fig.PDF"
    )
    with pytest.raises(UsageError, match=r"--still .*'\.jpg' is not supported; use one of \.png"):
        check_output_path(tmp_path / "still.jpg", "--still", suffixes=(".png",))
    with pytest.raises(UsageError, match="is a directory"):
        check_output_path(f"{tmp_path}/sub/", "--record")


def test_check_output_path_refuses_unwritable_places(tmp_path, monkeypatch):
    import hrc_drake.paths as paths

    monkeypatch.setattr(paths.os, "access", lambda path, mode: False)
    with pytest.raises(UsageError, match=r"--record .*not writable"):
        check_output_path(tmp_path / "run.html", "--record")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_check_output_path_refuses_a_read_only_folder(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    with pytest.raises(UsageError, match="not writable"):
        check_output_path(locked / "run.html", "--record")


@pytest.mark.parametrize("command", ["policy", "react", "table2"])
def test_policy_that_is_a_directory_or_missing_is_a_one_line_error(capsys, tmp_path, command):
    code, _, err = run(capsys, command, "--policy", str(tmp_path))
    _one_line_error(code, err, command, "is a directory", "policy.json")
    code, _, err = run(capsys, command, "--policy", str(tmp_path / "none.json"))
    _one_line_error(code, err, command, "not found")


def test_piping_into_head_prints_no_traceback():
    # The reader closes the pipe before the command writes: what `hrc-drake states | head -0` does.
    proc = subprocess.Popen(
        [sys.executable, "-m", "hrc_drake.cli", "states", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait() == 1
    assert err == ""


def test_plot_writes_pdf_and_refuses_other_extensions(capsys, tmp_path):
    out, again = tmp_path / "fig8.pdf", tmp_path / "again.pdf"
    assert run(capsys, "plot", "graph", "--out", str(out))[0] == 0
    assert run(capsys, "plot", "graph", "--out", str(again))[0] == 0
    assert out.read_bytes()[:5] == b"%PDF-"
    assert out.read_bytes() == again.read_bytes()  # no creation date: same figure, same file
    code, _, err = run(capsys, "plot", "graph", "--out", str(tmp_path / "fig8.jpg"))
    _one_line_error(code, err, "plot", "'.jpg' is not supported", ".png, .pdf, .svg")
    assert not (tmp_path / "fig8.jpg").exists()


def test_json_kinds_are_snake_case(capsys):
    for command in ("states", "policy"):
        code, out, _ = run(capsys, command, "--json")
        kinds = {r["kind"] for r in json.loads(out)}
        assert code == 0 and kinds == {"start", "normal", "terminal", "wrong", "dead_end"}
    _, out, _ = run(capsys, "states")
    assert "dead end" in out  # the table people read keeps the spaced label


def test_react_script_past_the_end_is_an_error(capsys):
    code, _, err = run(capsys, "react", "--operator", "9:F3")
    _one_line_error(code, err, "react", "9:F3", "after 3 decision step")
    code, _, err = run(capsys, "react", "--operator", "1:S23,2:F03,4:F1")
    _one_line_error(code, err, "react", "4:F1", "after 3 decision step")


def test_react_step_limit_from_forced_undos_blames_the_script(capsys):
    code, _, err = run(capsys, "react", "--operator", "1:F1,2:undo,3:F1,4:undo", "--max-steps", "4")
    _one_line_error(code, err, "react", "overrode the robot at step(s) [2, 4]", "undo at [2, 4]")
    assert "policy loops" not in err and "at least 7" in err
    # The same script with room to finish: 1 2 1 2 1 2 7 10.
    code, out, _ = run(capsys, "react", "--operator", "1:F1,2:undo,3:F1,4:undo", "--json")
    assert code == 0 and len(json.loads(out)["states"]) == 8


def test_a_looping_policy_is_still_called_one(flange_space):
    table = {seq: task for seq, task in exact_policy(flange_space).table.items()}
    table[("F1",)] = "undo"  # start -> F1 -> start -> ...
    looping = dataclasses.replace(exact_policy(flange_space), table=table)
    with pytest.raises(StepLimitError, match="the policy loops"):
        run_decisions(flange_space, looping, max_steps=10)


def test_react_keeps_refusing_infeasible_tasks(capsys):
    code, _, err = run(capsys, "react", "--operator", "1:F2,2:S23")
    _one_line_error(code, err, "react", "'S23' is not feasible", "feasible tasks are ['undo']")


def _policy_file(space, tmp_path, **changes):
    policy = exact_policy(space)
    table = dict(policy.table)
    table.update({tuple(k.split()): v for k, v in changes.items()})
    path = tmp_path / "policy.json"
    save_policy(dataclasses.replace(policy, table=table, method="edited"), path)
    return path


def test_table2_marks_rows_honestly(capsys, tmp_path, flange_space):
    # Square first from the empty base; undo after F3: row 4 becomes longer, row 7 n/a.
    path = _policy_file(flange_space, tmp_path, **{"": "S12", "F3": "undo"})
    code, out, _ = run(capsys, "table2", "--policy", str(path), "--json")
    rows = {r["row"]: r for r in json.loads(out)}
    assert code == 0
    assert rows[1]["policy"] == ["1", "5", "13", "17"] and rows[1]["compare"] == "equally_short"
    assert rows[4]["policy"] == ["1", "4", "1", "5", "13", "17"] and rows[4]["compare"] == "longer"
    assert rows[5]["compare"] == "same" and rows[5]["note"] is None
    assert rows[7]["policy"] is None and rows[7]["compare"] == "script_na"
    assert "F02 at step 3 is not feasible in state 13" in rows[7]["note"]
    code, out, _ = run(capsys, "table2", "--policy", str(path))
    lines = {line.split()[0]: line for line in out.splitlines()[2:]}
    assert "(another, equally short)" in lines["1"] and "<- longer" in lines["4"]
    assert "script n/a" in lines["7"] and "error" not in out
    assert "longer" not in lines["1"] + lines["5"]


def test_table2_script_past_the_end_and_shorter_rows(capsys, monkeypatch):
    def row(n, script, minimum):
        return types.SimpleNamespace(
            table2_row=n,
            name=f"row{n}",
            description="test",
            published=(),
            minimum_effort=tuple(minimum),
            script=script,
        )

    rows = [row(1, {5: "F3"}, ["1", "2", "7", "10"]), row(2, {}, ["1", "2", "1", "2", "7", "10"])]
    monkeypatch.setattr(task_commands, "table2_scenarios", lambda: rows)
    code, out, _ = run(capsys, "table2", "--json")
    first, second = json.loads(out)
    assert code == 0
    assert first["compare"] == "script_na" and "ends after 3 step(s)" in first["note"]
    assert second["compare"] == "shorter" and second["policy"] == ["1", "2", "7", "10"]
    _, out, _ = run(capsys, "table2")
    assert "shorter than the minimum-effort column" in out and "longer" not in out
