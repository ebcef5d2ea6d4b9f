"""The station and the controller over LCM check that they run the same scenario before the
first step (hrc_drake.cell.link.scenario_identity, the session's hello in
hrc_drake.cell.link.lockstep), and the station's hint is a command to paste."""

from __future__ import annotations

import re
import shlex
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hrc_drake import cli
from hrc_drake.cell.controller.build import connect_controller
from hrc_drake.cell.link.interface import end_station_session, make_cell_station_interface
from hrc_drake.cell.link.lockstep import LockstepTimeouts, ScenarioMismatch
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity, mismatch, spec_digest
from hrc_drake.cell.link.station_server import CellStationServer
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cli.scenario_args import scenario_from_args, scenario_options
from hrc_drake.scenario.schema import Scenario

sys.path.insert(0, str(Path(__file__).parent))
from fake_station import STEP, FakeController, make_fake_station

QUICK = LockstepTimeouts(start=3.0, step=3.0, resend=0.2)
REFUSAL = re.compile(r"hrc-drake (station|simulate): error: the (controller|station) \S+ scenario ")


def _udpm_url() -> str:
    """A host-local multicast URL on a port no one here uses now (tests may run in parallel)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return f"udpm://239.241.129.93:{port}?ttl=0"


def _identity(*argv: str) -> ScenarioIdentity:
    """The identity `hrc-drake simulate ARGV` states."""
    args = cli.build_parser().parse_args(["simulate", *argv])
    return ScenarioIdentity.of(scenario_from_args(args), scenario_options(args))


def test_a_mismatch_names_what_differs_from_each_side():
    """The issue's pair: row 1 --lean served, row 4 run. Each side says it in one line, the
    other's settings first; what only the controller reads may differ."""
    station = ScenarioIdentity.of(load_cell_scenario("row1-optimal", LEAN), ["--lean"])
    controller = ScenarioIdentity.of(load_cell_scenario("row4-forces-4"))
    said = mismatch(station, controller, "station")
    assert said == (
        'the controller runs scenario row4-forces-4 (operator.deviations [{"step": 1, "task": '
        '"F3"}], motion.hold_time 5.0, run.settle_time 0.3), this station serves row1-optimal '
        "--lean (operator.deviations [], motion.hold_time 0.5, run.settle_time 0.2): start both "
        "with the same scenario options"
    )
    assert mismatch(controller, station, "controller").startswith(
        "the station serves scenario row1-optimal --lean (operator.deviations [], "
        "motion.hold_time 0.5"
    )
    # Through the session message's JSON and back: the same identity.
    assert ScenarioIdentity.from_json(station.to_json()) == station
    assert ScenarioIdentity.from_json("{}") is None  # a station that serves no scenario
    assert mismatch(station, None, "controller") is None
    lean = _identity("--lean")
    assert lean.matches(
        _identity(
            "--lean", "--policy", "p.json", "--separation", "reactive", "--interaction", "wait"
        )
    )
    touch = mismatch(lean, _identity("--lean", "--interface", "touch"), "controller")
    assert touch.startswith(
        "the station serves scenario row1-optimal --lean --interface touch "
        "(interaction.interface touch), this controller runs row1-optimal --lean "
        "(interaction.interface pointer)"
    )


def test_the_spec_digest_ignores_comments_only(tmp_path):
    """A comment does not change the spec's digest; a value does."""
    flange = Path(cli.__file__).parents[2] / "models" / "assemblies" / "flange.yaml"
    text = flange.read_text()
    commented = tmp_path / "flange.yaml"
    commented.write_text("# a copy\n" + text)
    assert spec_digest(commented) == spec_digest(flange)
    changed = tmp_path / "other.yaml"
    changed.write_text(text.replace("name: flange\n", "name: flange-2\n", 1))
    assert spec_digest(changed) != spec_digest(flange)


def _run_fake(lcm: DrakeLcm, identity: ScenarioIdentity, duration: float = 0.1) -> dict:
    """The fake controller stating `identity` against a station on `lcm`; the session's
    report."""
    builder = DiagramBuilder()
    interface = builder.AddSystem(
        make_cell_station_interface(Scenario(), lcm, timeouts=QUICK, identity=identity)
    )
    connect_controller(builder, interface, builder.AddSystem(FakeController()))
    Simulator(builder.Build()).AdvanceTo(duration)
    return end_station_session(interface, timeout=3.0)


def test_the_hello_refuses_on_both_sides_and_lets_a_matching_pair_run():
    """Over memq (one process, the fake station): a station and a controller of different
    scenarios both stop with ScenarioMismatch before the first step; the same scenario runs."""
    served = ScenarioIdentity.of(Scenario(name="a"))
    lcm = DrakeLcm("memq://")
    server = CellStationServer(make_fake_station(), lcm, STEP, timeouts=QUICK, identity=served)
    with pytest.raises(ScenarioMismatch, match=r"^the station serves scenario a, this controller"):
        _run_fake(lcm, ScenarioIdentity.of(Scenario(name="b")))
    assert isinstance(server.error, ScenarioMismatch)
    assert str(server.error).startswith("the controller runs scenario b, this station serves a")
    assert server.root_context.get_time() == 0.0  # it never stepped
    lcm = DrakeLcm("memq://")
    server = CellStationServer(make_fake_station(), lcm, STEP, timeouts=QUICK, identity=served)
    assert _run_fake(lcm, served)["exchanges"] == 10
    assert server.error is None


def _hrc_drake(*argv: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "hrc_drake.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def test_a_mismatched_pair_is_refused_on_both_sides_in_one_line():
    """The issue's pair as two commands: both exit 2 with one line each, naming what differs."""
    url = _udpm_url()
    station = _hrc_drake(
        "station", "--scenario", "row1-optimal", "--lean", "--lcm", url, "--timeout", "60"
    )
    try:
        controller = _hrc_drake("simulate", "--scenario", "row4-forces-4", "--station-lcm", url)
        c_out, c_err = controller.communicate(timeout=120)
        s_out, s_err = station.communicate(timeout=60)
    finally:
        station.kill()
    assert (controller.returncode, station.returncode) == (2, 2), (c_err, s_err)
    assert c_out == s_out == ""
    [c_line] = c_err.strip().splitlines()
    hint, s_line = s_err.strip().splitlines()
    assert hint.startswith("station row1-optimal: serving on ")
    for line in (c_line, s_line):
        assert REFUSAL.match(line), line
        assert "row4-forces-4" in line and "row1-optimal --lean" in line
        assert "motion.hold_time 0.5" in line and "motion.hold_time 5.0" in line
        assert line.endswith(": start both with the same scenario options")


def test_the_station_hint_is_a_command_to_paste():
    """The hint gives every scenario option the station got, and the URL quoted (its `?` is a
    glob in zsh): parsed as a shell would, it is a controller of the station's very scenario."""
    url = _udpm_url()
    options = ["--scenario", "row1-optimal", "--lean", "--scenario-text", "{run: {max_steps: 20}}"]
    station = _hrc_drake("station", *options, "--operator", "1:F3", "--lcm", url, "--timeout", "1")
    _, err = station.communicate(timeout=120)
    hint = err.splitlines()[0]
    assert f"--station-lcm {shlex.quote(url)}" in hint and "'" in shlex.quote(url)
    command = shlex.split(hint.split("start the controller with: ", 1)[1])
    assert command[:2] == ["hrc-drake", "simulate"] and "--lean" in command
    args = cli.build_parser().parse_args(command[1:])
    assert args.station_lcm == url
    station_args = cli.build_parser().parse_args(["station", *options, "--operator", "1:F3"])
    served = ScenarioIdentity.of(scenario_from_args(station_args))
    assert ScenarioIdentity.of(scenario_from_args(args)).matches(served)
