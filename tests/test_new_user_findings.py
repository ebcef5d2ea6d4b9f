"""What a second new user found (issue 51, item 5) beyond the careless inputs of
`test_careless_inputs.py`: each test here fails on the code before the fix (the finding is in
its docstring). None of them simulates: the commands are called at unit level or on the task
level's tiny runs."""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
from importlib.metadata import version
from pathlib import Path
from types import SimpleNamespace

import pytest

from hrc_drake.cli import build_parser, main
from hrc_drake.cli import evaluate as evaluate_command
from hrc_drake.cli.scenario_args import scenario_from_args
from hrc_drake.cli.simulate import operator_summary

REPO = Path(__file__).resolve().parent.parent
REPLAYED = (
    "{operator: {deviations: [], model: mistake-prone, params: {p: 0.5}, seed: 307626447, "
    "delay_seed: [2, 1]}, decider: {name: mpc, seed: 2}}"
)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_replayed_run_describes_its_own_operator():
    """Before: the replay of a failing `evaluate --cell` run printed row 1's description,
    "nothing: the operator follows the robot", for a mistake-prone operator."""
    argv = ["simulate", "--scenario", "row1-optimal", "--lean", "--scenario-text", REPLAYED]
    description = scenario_from_args(build_parser().parse_args(argv)).description
    assert description == "a mistake-prone operator (p=0.5, seed 307626447) (--scenario-text)"
    # Text that leaves the operator alone leaves the scenario's own description.
    argv = ["simulate", "--scenario", "row1-optimal", "--scenario-text", "{run: {max_steps: 9}}"]
    plain = scenario_from_args(build_parser().parse_args(argv)).description
    assert plain == "nothing: the operator follows the robot"


def test_the_summary_says_where_the_operator_did_not_perform_the_proposal():
    """Before: the summary's steps alone showed it, and the header said the operator follows."""

    def task(step, proposed, indicated):
        return SimpleNamespace(step=step, proposed=proposed, indicated=indicated)

    tasks = [task(1, "F2", "F2"), task(2, "F3", "F1"), task(3, "S12", "S12")]
    assert operator_summary(tasks) == (
        "performed another task than proposed at 1 of 3 steps: step 2 F1 instead of F3"
    )
    assert operator_summary(tasks[:1]) == "followed the robot's proposal at every step (1)"
    assert operator_summary([]) == "no task was done"


def _empty_report(runs: int = 2) -> dict:
    """A cell report in which no run completed (as `--scenario-text '{run: {max_sim_time:
    10}}'` gives), with its failures."""
    failure = {"run": 0, "seed": 1, "operator_model": "follows", "params": {}, "stop": "x"}
    return {
        "decider": "exact", "operator_model": "follows", "params": {}, "runs": runs,
        "completed": 0, "times": [], "interrupted": False, "failures": [failure],
    }  # fmt: skip


def test_plot_with_no_completed_run_says_so_and_writes_nothing(capsys, tmp_path):
    """Before: `evaluate --cell --plot` wrote nothing and said nothing when no run completed."""
    plot = tmp_path / "times.png"
    args = argparse.Namespace(json=True)
    assert evaluate_command._report(args, _empty_report(), plot) == 1  # the runs failed
    err = capsys.readouterr().err.splitlines()
    assert not plot.exists()
    assert err[0] == (
        f"hrc-drake evaluate: --plot {plot}: nothing to plot, not written: none of the 2 run(s) "
        "completed (the histogram shows completed runs' times); see the failures and their "
        "replay commands; a larger run.max_sim_time or fewer mistakes let runs finish"
    )
    # An earlier plot at that path is kept, and the line says that it is an earlier one.
    plot.write_bytes(b"\x89PNG earlier")
    evaluate_command._report(args, _empty_report(), plot)
    assert "(the file there is an earlier one, left as it was)" in capsys.readouterr().err
    assert plot.read_bytes() == b"\x89PNG earlier"


def test_params_are_typed_in_the_report(capsys, tmp_path, toy_costs):
    """Before: `--param p=0.3` was reported as the text "0.3"."""
    from hrc_drake.tasks.costs import save_cost_table

    assert evaluate_command.parse_params(["p=0.3", "n=2", "b=true", "order=S23"]) == {
        "p": 0.3, "n": 2, "b": True, "order": "S23",
    }  # fmt: skip
    costs = tmp_path / "costs.json"
    save_cost_table(toy_costs, costs)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "mistake-prone"]
    argv += ["--param", "p=0.3", "--runs", "5", "--costs", costs]
    code, out, _ = run(capsys, *argv, "--json")
    assert code == 0 and json.loads(out)["params"] == {"p": 0.3}
    code, out, _ = run(capsys, *argv)
    assert re.search(r"^params +p=0.3$", out, re.M), out


def test_the_text_report_gives_each_figure_its_unit(capsys, tmp_path, toy_costs):
    """Before: `mean_time 43.944`, `mean_tasks 3.76`: seconds or tasks, and of what?"""
    from hrc_drake.tasks.costs import save_cost_table

    costs = tmp_path / "costs.json"
    save_cost_table(toy_costs, costs)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--runs", "3"]
    code, out, _ = run(capsys, *argv, "--costs", costs)
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert code == 0
    for key, unit in evaluate_command.REPORT_UNITS.items():
        if key in lines:
            assert lines[key].endswith(f" {unit}"), lines[key]
    assert re.search(r"^mean_time +[\d.]+ s per completed run$", lines["mean_time"])
    assert re.search(r"^mean_tasks +[\d.]+ tasks per run$", lines["mean_tasks"])


def test_the_docs_failure_example_is_what_the_report_prints():
    """Before: the example in docs/evaluation.md showed `failures 1` and states the command no
    longer gave. Every figure line it quotes carries its unit, as `print_report` prints it."""
    text = (REPO / "docs" / "evaluation.md").read_text()
    block = text.split("--runs 2 --seed 2 --scenario-text '{run: {max_sim_time: 22}}'", 1)[1]
    block = block.split("```", 1)[0]
    quoted = [line for line in block.splitlines() if re.match(r"^[a-z_]+ {2,}", line)]
    assert len(quoted) >= 3
    for line in quoted:
        key, value = line.split(None, 1)
        if key in evaluate_command.REPORT_UNITS:
            assert value.endswith(evaluate_command.REPORT_UNITS[key]), line
    failing = re.findall(r"^  run (\d+) \(mistake-prone p=0.5, seed \d+\)", block, re.M)
    assert f"failures               {len(failing)} runs" in block


def test_version_prints_the_package_version(capsys):
    """Before: `hrc-drake --version` was "the following arguments are required: command"."""
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out == f"hrc-drake {version('hrc_drake')}\n"


@pytest.mark.parametrize(
    ("flags", "record"),
    [([], "out/row8-forces-4-then-8.html"), (["--lean"], "out/row8-forces-4-then-8-lean.html")],
)
def test_demo_lean_keeps_the_full_runs_recording(tmp_path, flags, record):
    """Before: `demo.sh --lean` wrote out/row8-forces-4-then-8.html over the full run's. The
    script runs in a copy of the checkout whose installed `hrc-drake` prints its arguments."""
    (tmp_path / "tools").mkdir()
    shutil.copy(REPO / "tools" / "demo.sh", tmp_path / "tools" / "demo.sh")
    (tmp_path / "pyproject.toml").write_text("")
    bin_dir = tmp_path / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    for name, body in (("python", "exit 0"), ("hrc-drake", 'echo "$@"')):
        (bin_dir / name).write_text(f"#!/bin/sh\n{body}\n")
        (bin_dir / name).chmod(0o755)
    stamp = tmp_path / ".venv" / ".hrc_drake-demo-installed"
    stamp.write_text("")
    os.utime(tmp_path / "pyproject.toml", (0, 0))  # the install is current: no pip
    done = subprocess.run(
        ["bash", str(tmp_path / "tools" / "demo.sh"), *flags],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [
        "simulate", "--scenario", "row8-forces-4-then-8", "--record", record, *flags,
    ]  # fmt: skip
    assert f"demo: recording to {record}" in done.stderr
