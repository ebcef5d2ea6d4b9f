"""`hrc-drake simulate` as a user runs it, the scenario catalogue, and the example scripts."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cli import main
from hrc_drake.resources import scenarios_dir
from hrc_drake.scenario.load import load_scenario
from hrc_drake.tasks.decide import run_decisions
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import load_spec

REPO = Path(__file__).resolve().parent.parent
CATALOGUE = sorted(scenarios_dir().glob("*.yaml"))


def _simulate(capsys, *args):
    code = main(["simulate", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.slow
def test_simulate_json_has_the_documented_keys(capsys):
    code, out, _ = _simulate(capsys, "--scenario", "row4-forces-4", "--lean", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["states"] == [[], ["F3"], ["F3", "S12"], ["F3", "S12", "F01"]]
    assert data["terminal"] is True and data["collisions"] == 0
    assert [s["operator"] for s in data["steps"]] == ["F3", "S12", "F01"]
    assert [s["proposed"] for s in data["steps"]] == ["F1", "S12", "F01"]
    assert all(s["observed"] == s["operator"] and s["sim_time"] > 0 for s in data["steps"])
    for key in ("sim_time", "wall_time", "real_time_factor"):
        assert data[key] > 0
    # Idle is simulated time: simulated time stands still while the planner works, so the robot
    # idles one Supervisor update whatever the machine; the wall-clock wait is reported apart.
    period = load_scenario("row4-forces-4").run.period
    assert all(s["idle_time"] == pytest.approx(period) for s in data["steps"])
    assert data["mean_idle"] == pytest.approx(period)
    assert all(s["wall_idle_time"] >= 0 for s in data["steps"]) and data["wall_mean_idle"] >= 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--record", "{tmp}"], "--record {tmp}: is a directory"),
        (["--record", "{tmp}/no/such/dir/x.html"], "does not exist"),
        (["--record", "{tmp}/x.txt"], "'.txt' is not supported; use one of .html"),
        (["--still", "{tmp}/x.jpg"], "use one of .png"),
        (["--still", "{tmp}/x.png", "--still-time", "-1"], "--still-time -1.0: give a time"),
        (["--scenario-text", "{{motion: {{hold_tme: 1}}}}"], "hold_tme"),
        (["--scenario-text", "{{run: {{max_steps: 2.5}}}}"], "max_steps"),
        (["--operator", "1:F9"], "'F9' is not a placement"),
        (["--operator", "1-F3"], "STEP:TASK"),
        (["--operator", "7:F1"], "step(s) 7:F1 come after the end of the run"),
        (["--operator", "1:S23,2:F1"], "'F1' is not feasible"),
        (["--scenario", "no-such-row"], "not found; known scenarios"),
        (["--policy", "{tmp}"], "{tmp}"),
        (["--assembly", "{tmp}/none.yaml"], "none.yaml"),
    ],
)
def test_bad_input_is_one_line_before_any_work(capsys, tmp_path, args, message):
    args = [a.format(tmp=tmp_path) for a in args]
    code, out, err = _simulate(capsys, *args, "--lean")
    assert code == 2, (out, err)
    assert message.format(tmp=tmp_path) in err
    assert "Traceback" not in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("pace", "message"),
    [("0", "0 is not a pace; give a real-time rate > 0"), ("fast", "'fast' is not a number")],
)
def test_a_live_pace_that_is_no_pace_is_one_line(capsys, pace, message):
    """`--live PACE` takes a real-time rate > 0; anything else is refused by the parser, in
    one line naming the flag, before any work."""
    with pytest.raises(SystemExit) as exit_:
        main(["simulate", "--live", pace, "--lean"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert f"argument --live: {message}" in err and err.count("\n") == 1


@pytest.mark.slow
def test_still_past_the_end_of_the_run_is_an_error(capsys, tmp_path):
    still = tmp_path / "late.png"
    code, _, err = _simulate(
        capsys,
        "--scenario",
        "row5-forces-5",
        "--lean",
        "--still",
        str(still),
        "--still-time",
        "999",
    )
    assert code == 2 and "past the end of the run" in err
    assert not still.exists()


def test_a_spec_that_does_not_fit_the_cell_is_refused_by_simulate(capsys, tmp_path):
    spec = tmp_path / "far.yaml"
    flange = (REPO / "models" / "assemblies" / "flange.yaml").read_text()
    spec.write_text(
        flange + "cell:\n  plate_position: [0.30, 0.35, 0.0]\n  tray_position: [0.2, -0.25, 0]\n"
    )
    code, _, err = _simulate(capsys, "--assembly", str(spec), "--lean")
    assert code == 2
    assert "cannot reach F3 (slot 3)" in err and "cell.plate_position" in err


@pytest.mark.parametrize("path", CATALOGUE, ids=[p.stem for p in CATALOGUE])
def test_scenario_catalogue(path):
    """Every scenario loads the same with both loaders, runs through the decision loop, and
    starts in the cell (a few simulated seconds, as Drake's hardware_sim tests its catalogue)."""
    plain = load_scenario(path)
    typed = load_cell_scenario(path)
    assert dataclasses.asdict(plain) == dataclasses.asdict(typed)
    space = generate_states(load_spec(plain.assembly_path))
    states, _ = run_decisions(space, exact_policy(space), plain.operator_for(space))
    if plain.expected.minimum_effort:
        assert [space.name(space.index(s)) for s in states] == plain.expected.minimum_effort
    short = load_cell_scenario(path, [LEAN, "{run: {max_sim_time: 3.0}}"])
    result = run_scenario(short)
    assert result.collisions == []
    assert result.tasks == [] or result.tasks[0].proposed
    assert result.error is None or "no terminal state within 3.0 s" in result.error


EXAMPLES = [
    [
        "build_cell_still.py",
        "--assembly",
        "models/assemblies/four-slot.yaml",
        "--out",
        "{tmp}/c.png",
    ],
    ["plan_one_task.py", "--configuration", "F1", "--task", "S23"],
    ["custom_operator.py", "--lean", "--assembly", "models/assemblies/four-slot.yaml"],
]


@pytest.mark.slow
@pytest.mark.parametrize("example", EXAMPLES, ids=[e[0] for e in EXAMPLES])
def test_examples_run(example, tmp_path):
    args = [a.format(tmp=tmp_path) for a in example]
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / args[0]), *args[1:]],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    if args[0] == "build_cell_still.py":
        assert (tmp_path / "c.png").stat().st_size > 10_000
    if args[0] == "plan_one_task.py":
        assert "valid: True" in done.stdout
    if args[0] == "custom_operator.py":
        assert "terminal: True; robot collisions: 0" in done.stdout
        assert "operator did S34" in done.stdout
