"""Ctrl-C during `hrc-drake simulate`, live or headless: one line, no traceback, and the
recording and the JSON of what ran, marked interrupted."""

from __future__ import annotations

import base64
import json
import re

import pytest
from simulate_process import SimulateProcess

pytestmark = pytest.mark.slow

TIMEOUT = 180.0  # s; a busy CI machine plans and simulates slowly


def _interrupted(run: SimulateProcess, record) -> dict:
    """Send Ctrl-C; check the end: status 130, one line, the recording, the JSON."""
    run.interrupt()
    code, out, err = run.finish(TIMEOUT)
    assert code == 130, err[-5:]
    assert not any("Traceback" in line for line in err), err
    assert err[-1].startswith("hrc-drake simulate: interrupted at "), err[-3:]
    assert "Ctrl-C" in err[-1] and sum("interrupted" in line for line in err) == 1, err
    data = json.loads(out)
    assert data["interrupted"] is True and data["terminal"] is False
    assert data["error"] == err[-1].removeprefix("hrc-drake simulate: ")
    assert data["recording"] == str(record)
    assert b"set_animation" in _recorded_commands(record.read_text())
    return data


def _recorded_commands(html: str) -> bytes:
    """The Meshcat commands a static page replays (base64 msgpack blobs), concatenated."""
    blobs = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)
    return b"".join(base64.b64decode(blob) for blob in blobs)


def test_ctrl_c_at_a_live_prompt_keeps_the_recording_and_the_json(tmp_path):
    """Interrupted while the robot waits for the person's first click: nothing was done yet,
    and the page's buttons are gone."""
    record = tmp_path / "live.html"
    args = ["--live", "--lean", "--port", "0", "--record", str(record), "--json"]
    run = SimulateProcess(*args)
    try:
        run.wait_for_line(r"^step 1: the robot proposes F1\b", TIMEOUT)
        data = _interrupted(run, record)
    finally:
        run.kill()
    assert data["names"] == ["1"] and data["steps"] == []


def test_ctrl_c_during_a_headless_run_keeps_what_ran(tmp_path):
    """Interrupted once the simulation is under way (its progress line shows): the JSON holds
    the simulated time reached."""
    record = tmp_path / "run.html"
    run = SimulateProcess("--lean", "--record", str(record), "--json")
    try:
        run.wait_for_line(r"cell row1-optimal: sim s", TIMEOUT)
        data = _interrupted(run, record)
    finally:
        run.kill()
    assert data["sim_time"] > 0 and data["names"][0] == "1"


def test_ctrl_c_ends_a_run_started_with_sigint_ignored(tmp_path):
    """A shell that starts a job in the background hands it SIGINT ignored (and Python would
    keep it so): `simulate` takes Ctrl-C back, so a SIGINT still ends the run."""
    import os
    import signal
    import subprocess
    import time

    from simulate_process import hrc_drake_command

    args = [*hrc_drake_command(), "simulate", "--lean", "--json"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with subprocess.Popen(
        args,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    ) as run:
        deadline = time.monotonic() + TIMEOUT
        line = ""
        while "cell row1-optimal: sim s" not in line and time.monotonic() < deadline:
            line = run.stderr.readline()
        run.send_signal(signal.SIGINT)
        out, err = run.communicate(timeout=TIMEOUT)
    assert run.returncode == 130, err[-300:]
    assert json.loads(out)["interrupted"] is True


def _children(pid: int) -> list[int]:
    """The processes whose parent is `pid` (from /proc: psutil is not a dependency)."""
    from pathlib import Path

    out = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            text = status.read_text()
        except OSError:
            continue  # ended while listed
        if f"\nPPid:\t{pid}\n" in text:
            out.append(int(status.parent.name))
    return out


def _alive(pid: int) -> bool:
    """Whether process `pid` exists and is not a zombie."""
    from pathlib import Path

    try:
        return "\nState:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False


def _ended_by_ctrl_c(run: SimulateProcess, command: str) -> tuple[str, list[str]]:
    """Send Ctrl-C; check status 130, one `interrupted` line last, no traceback; stdout and
    stderr lines."""
    run.interrupt()
    code, out, err = run.finish(TIMEOUT)
    assert code == 130, err[-5:]
    assert not any("Traceback" in line for line in err), err
    assert err[-1].startswith(f"hrc-drake {command}: interrupted"), err[-3:]
    assert sum("interrupted" in line for line in err) == 1, err
    return out, err


@pytest.fixture
def toy_costs_file(tmp_path, toy_costs):
    """The hand-made cost table in a file: the deciders need no motion planning."""
    from hrc_drake.tasks.costs import save_cost_table

    path = tmp_path / "toy-costs.json"
    save_cost_table(toy_costs, path)
    return path


def test_ctrl_c_ends_cell_evaluation_with_the_runs_done_and_no_workers(toy_costs_file):
    """Interrupted once the first of four runs is done, two still running in workers: the
    report of the runs done, marked interrupted, and the workers gone."""
    import time

    args = ["--cell", "--lean", "--runs", "4", "--workers", "2", "--json"]
    args += ["--decider", "exact", "--operator-model", "follows", "--costs", str(toy_costs_file)]
    run = SimulateProcess(*args, "--scenario-text", "{body: {enabled: false}}", command="evaluate")
    try:
        run.wait_for_line(r"cell exact vs follows: run 1/4", TIMEOUT)
        workers = _children(run.proc.pid)
        assert len(workers) >= 2  # the pool's two (and multiprocessing's resource tracker)
        out, err = _ended_by_ctrl_c(run, "evaluate")
    finally:
        run.kill()
    report = json.loads(out)
    assert report["interrupted"] is True and report["runs_requested"] == 4
    assert 1 <= report["runs"] < 4 and report["completed"] == report["runs"]
    assert err[-1] == f"hrc-drake evaluate: interrupted after {report['runs']} of 4 runs"
    deadline = time.monotonic() + 10.0
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [p for p in workers if _alive(p)]


def test_ctrl_c_ends_task_level_evaluation_with_the_runs_done(toy_costs_file):
    args = ["--decider", "exact", "--operator-model", "random", "--runs", "1000000", "--json"]
    run = SimulateProcess(*args, "--costs", str(toy_costs_file), command="evaluate")
    try:
        run.wait_for_line(r"evaluate exact vs random: run \d+/1000000", TIMEOUT)
        out, _err = _ended_by_ctrl_c(run, "evaluate")
    finally:
        run.kill()
    report = json.loads(out)
    assert report["interrupted"] is True and 0 < report["runs"] < 1000000


def test_ctrl_c_ends_costs_leaving_the_previous_table(toy_costs_file):
    """Interrupted while planning: the previous table in the file is left as it was."""
    before = toy_costs_file.read_bytes()
    run = SimulateProcess("--out", str(toy_costs_file), command="costs")
    try:
        run.wait_for_line(r"planning task edges and bets: plan \d+", TIMEOUT)
        _ended_by_ctrl_c(run, "costs")
    finally:
        run.kill()
    assert toy_costs_file.read_bytes() == before
    assert [p.name for p in toy_costs_file.parent.iterdir()] == [toy_costs_file.name]
