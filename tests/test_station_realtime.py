"""The cell station over LCM in real time (hrc_drake.cell.link.realtime, realtime_client,
realtime_server): the staleness and silence rules on synthetic stamps, the shared clock, the
station walking to a command it is late for, the hello that refuses a pair that runs the link
otherwise; a row-1 pair in two processes; and each side ending in one line when the other is
killed."""

from __future__ import annotations

import json
import re
import shlex
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from hrc_drake.cell.controller.build import connect_controller
from hrc_drake.cell.link import lcm_messages as lm
from hrc_drake.cell.link.channels import SIM_CONTACTS
from hrc_drake.cell.link.lockstep import (
    LockstepTimeouts,
    ScenarioMismatch,
    StationLinkError,
    identity_text,
    link_mismatch,
    their_identity,
)
from hrc_drake.cell.link.realtime import (
    DEVICE_RATES,
    SILENCE,
    LinkClock,
    UpdateClock,
    age,
    channel_latencies,
    channel_rates,
    judge,
    silent,
    stale_after,
)
from hrc_drake.cell.link.realtime_client import make_realtime_station_interface, restamp
from hrc_drake.cell.link.realtime_server import ArmSegment, measured_at
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.link.station_server import CellStationServer
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.hri.messages import Prompt
from hrc_drake.scenario.schema import Scenario
from hrc_drake.scenario.sensors import CAMERA

sys.path.insert(0, str(Path(__file__).parent))
from fake_station import STEP, FakeController, make_fake_station
from simulate_process import SimulateProcess

FAKE = Path(__file__).parent / "fake_station.py"
QUICK = LockstepTimeouts(start=20.0, step=5.0, resend=0.2)
MS = 1000  # us


def _udpm_url() -> str:
    """A host-local multicast URL on a port no one here uses now (tests may run in parallel)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return f"udpm://239.241.129.94:{port}?ttl=0"


# --- the rules, on synthetic stamps -----------------------------------------------------------
def test_a_reading_is_stale_past_three_periods_and_50_ms():
    """The arm at RTDE's 500 Hz is stale past 56 ms, the body at 30 Hz past 150 ms (both paced
    at 1; at pace 2 the periods count half); nothing else stops the robot."""
    rates = channel_rates(Scenario())
    assert stale_after(rates["UR3_STATUS"], 1.0) == pytest.approx(0.056)
    assert stale_after(rates["OPERATOR_BODY"], 1.0) == pytest.approx(0.15)
    assert stale_after(rates["UR3_STATUS"], 2.0) == pytest.approx(0.053)
    now = 1_700_000_000_000_000
    fresh = {"UR3_STATUS": now - 55 * MS, "OPERATOR_BODY": now - 149 * MS, "RG2_STATUS": 0}
    assert not judge(fresh, now, rates, 1.0).any
    late = {**fresh, "UR3_STATUS": now - 57 * MS}
    judged = judge(late, now, rates, 1.0)
    assert [c for c, _, _ in judged.stale] == ["UR3_STATUS"]
    assert judged.words() == "UR3_STATUS 0.057 s old (bound 0.056 s)"
    both = {**late, "OPERATOR_BODY": now - 151 * MS}
    assert [c for c, _, _ in judge(both, now, rates, 1.0).stale] == ["UR3_STATUS", "OPERATOR_BODY"]
    # A stamp from a clock a little ahead is not negative age.
    assert not judge({"UR3_STATUS": now + 5 * MS}, now, rates, 1.0).any


def test_a_sensor_latency_the_scenario_states_widens_the_bound():
    """Under `realistic` the body tracker's readings are stamped when taken and sent up to
    100 ms later: the body is stale past 250 ms, not 150 ms (else a tracker on time would stop
    the robot); the arm's bound grows by its own few milliseconds."""
    scenario = load_cell_scenario("row1-optimal", "{sensors: {preset: realistic}}")
    rates, latencies = channel_rates(scenario), channel_latencies(scenario)
    assert latencies["OPERATOR_BODY"] == pytest.approx(0.1)
    assert channel_latencies(Scenario()) == {}
    now = 1_700_000_000_000_000
    on_time = {"UR3_STATUS": now, "OPERATOR_BODY": now - 240 * MS}
    assert judge(on_time, now, rates, 1.0).any  # without the latency: stale
    assert not judge(on_time, now, rates, 1.0, latencies).any
    late = {**on_time, "OPERATOR_BODY": now - 260 * MS}
    assert judge(late, now, rates, 1.0, latencies).words() == (
        "OPERATOR_BODY 0.260 s old (bound 0.250 s)"
    )


def test_rates_come_from_the_sensors_section_where_it_states_them():
    """Under `ideal` the devices' figures; a sensor model's rate where the scenario gives one
    (the camera's for the configuration under `configuration: camera`);
        the commands and the touching pairs at the controller's rate."""
    scenario = Scenario()
    rates = channel_rates(scenario)
    assert {k: rates[k] for k in DEVICE_RATES} == DEVICE_RATES
    assert rates["UR3_COMMAND"] == rates["HRI_PROMPT"] == 1 / scenario.run.period
    assert rates[SIM_CONTACTS.channel] == 1 / scenario.run.period
    scenario = load_cell_scenario(
        "row1-optimal", "{sensors: {preset: realistic, body: {rate: 15}, rg2: {rate: 50}}}"
    )
    rates = channel_rates(scenario)
    assert (rates["OPERATOR_BODY"], rates["RG2_STATUS"], rates["UR3_STATUS"]) == (15, 50, 500)
    scenario = load_cell_scenario(
        "row1-optimal",
        "{sensors: {preset: realistic, configuration: camera, wrench: {rate: 250}}}",
    )
    rates = channel_rates(scenario)
    assert rates["UR3_TCP_FORCE"] == 250 and rates["CELL_CONFIGURATION"] == CAMERA.rate


def test_silence_is_no_arrival_for_two_seconds():
    """The channel quiet longest is named once it has been quiet past SILENCE."""
    assert silent({}, 10.0) is None
    assert silent({"UR3_STATUS": 9.0, "RG2_STATUS": 8.5}, 10.0) is None
    assert silent({"UR3_STATUS": 9.0, "RG2_STATUS": 7.9}, 10.0) == (
        "RG2_STATUS",
        pytest.approx(2.1),
    )
    assert SILENCE == 2.0


def test_the_link_clock_stamps_the_wall_time_a_simulated_instant_stands_for():
    wall = [5_000_000]
    clock = LinkClock(2.0, lambda: wall[0])
    assert clock.stamp(3.0) == 5_000_000  # not started: the wall clock itself
    clock.start(1.0)
    wall[0] = 9_000_000
    # 1 s of simulated time at pace 2 is half a second of the wall clock, however late it is.
    assert clock.stamp(2.0) == 5_500_000 and clock.now() == 9_000_000


def test_a_camera_verdict_and_a_body_keep_their_measurement_time_across_the_link():
    """The station stamps a body and a camera's configuration when they were measured, the
    controller puts that back on its own clock (now less the message's age): a verdict from a
    frame before the parts came to rest is not taken as current (it was, as if made now)."""
    from hrc_drake.cell.ports import NOBODY, CellConfiguration

    wall = [5_000_000]
    station = LinkClock(1.0, lambda: wall[0])
    station.start(0.0)
    frame = CellConfiguration(stamp=11.8)  # the camera's newest agreeing frame
    message = lm.configuration_message(station.stamp(measured_at(12.0, frame)), frame)
    assert message.utime == 5_000_000 + 11_800_000  # its frame's, not the publish's 12.0 s
    assert measured_at(12.0, CellConfiguration()) == 12.0  # the contact sensor: now
    assert measured_at(12.0, NOBODY) == 12.0
    # The controller, at its 12.05 s, hears it 0.25 s old on the shared clock.
    (decoded,) = lm.configuration_value(message)
    assert decoded.stamp is None  # the message alone carries no stamp of the reading's own
    now = message.utime + 250 * MS
    seen = restamp(decoded, 12.05, age(message.utime, now), 1.0)
    assert seen.stamp == pytest.approx(11.8)
    assert not seen.current_at(11.9) and seen.current_at(11.8)
    # At half pace, 0.25 s of wall time is 0.125 s of simulated time.
    assert restamp(decoded, 12.05, 0.25, 0.5).stamp == pytest.approx(11.925)


def test_a_late_station_walks_to_the_newest_command_at_its_commanded_pace():
    """From the command it held when the newest came to the newest, over their stamps' interval;
    the newest as it is once due (up to `early` ahead)."""
    q0, q1 = np.zeros(6), np.full(6, 0.3)
    v0, v1 = np.zeros(6), np.full(6, 1.0)
    arm = ArmSegment(q0, v0, 1_000_000, q1, v1, 1_300_000)
    q, v = arm.at(1_100_000, early=10 * MS)
    assert q == pytest.approx(np.full(6, 0.1)) and v == pytest.approx(np.full(6, 1 / 3))
    assert arm.at(1_291_000, early=10 * MS)[0] == pytest.approx(q1)
    assert arm.at(1_000_000, early=10 * MS)[0] == pytest.approx(q0)


def test_the_update_clock_reports_period_jitter_deadlines_and_stale_stops():
    clock = UpdateClock(0.02, 1.0)
    walls = [100.0, 100.02, 100.041, 100.06, 100.115, 100.12]
    stale = judge({"UR3_STATUS": 0}, 10**9, channel_rates(Scenario()), 1.0)
    fresh = judge({}, 0, {}, 1.0)
    for k, wall in enumerate(walls):
        clock.note(0.02 * k, wall, stale if k in (2, 3) else fresh)
    figures = clock.figures()
    assert figures.updates == 6 and figures.period == pytest.approx(0.024)
    assert figures.jitter_max == pytest.approx(0.035)
    # The fifth update ran 35 ms after it was due: later than one period.
    assert figures.missed_deadlines == 1 and figures.max_lateness == pytest.approx(0.035)
    assert figures.stale_stops == 1 and figures.stale_time == pytest.approx(0.04)
    assert figures.stale_events[0].startswith("0.04: UR3_STATUS ")
    assert figures.stale_events[1] == "0.08: fresh readings: resumes"
    assert set(figures.to_json()) >= {"period", "jitter", "missed_deadlines", "pace_achieved"}


# --- the hello -------------------------------------------------------------------------------
def test_the_hello_carries_the_mode_and_a_pair_that_differs_is_refused():
    identity = ScenarioIdentity.of(Scenario(name="a"))
    realtime = lm.session_message(0, "hello", identity_text(identity, 1.0))
    lockstep = lm.session_message(0, "hello", identity_text(identity))
    assert their_identity(realtime) == identity  # the mode beside the identity
    assert link_mismatch(1.0, realtime, "station") is None
    assert link_mismatch(None, realtime, "station") == (
        "the controller runs in real time (--realtime 1), this station serves in lockstep: "
        "start both with the same --realtime option, or neither with it"
    )
    assert link_mismatch(2.0, lockstep, "controller").startswith(
        "the station serves in lockstep, this controller runs in real time (--realtime 2)"
    )
    # A driver's `{}` states no mode: any controller runs against it; so does a stand-in's.
    anyone = lm.session_message(0, "hello", identity_text(None, 1.0))
    assert link_mismatch(None, lm.session_message(0, "hello", "{}"), "station") is None
    assert their_identity(anyone) is None


def test_a_real_time_controller_is_refused_by_a_lockstep_station():
    """Over memq, the lockstep's fake station serving scenario a: both sides refuse before the
    first step, each naming the two modes."""
    served = ScenarioIdentity.of(Scenario(name="a"))
    lcm = DrakeLcm("memq://")
    server = CellStationServer(make_fake_station(), lcm, STEP, timeouts=QUICK, identity=served)
    link = make_realtime_station_interface(Scenario(name="a"), lcm, timeouts=QUICK)
    with pytest.raises(ScenarioMismatch, match=r"^the station serves in lockstep, this controller"):
        link.session.greet()
    assert isinstance(server.error, ScenarioMismatch)
    assert "the controller runs in real time (--realtime 1)" in str(server.error)


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["simulate", "--lean", "--realtime"], "--realtime paces the controller against"),
        (["station", "--realtime", "0"], "argument --realtime: 0 is not a pace"),
    ],
)
def test_bad_realtime_options_are_refused_in_one_line(argv, said):
    result = subprocess.run(
        [sys.executable, "-m", "hrc_drake.cli", *argv], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 2, result.stderr
    [line] = result.stderr.strip().splitlines()
    assert line.startswith(f"hrc-drake {argv[0]}: error: ") and said in line


# --- two processes ---------------------------------------------------------------------------
def _fake_controller(url: str, scenario: Scenario, identity=None):
    """The fake controller against the station on `url` in real time: (simulator, session)."""
    link = make_realtime_station_interface(
        scenario, DrakeLcm(url), timeouts=QUICK, identity=identity
    )
    builder = DiagramBuilder()
    interface = builder.AddSystem(link.diagram)
    controller = builder.AddSystem(FakeController())
    connect_controller(builder, interface, controller)
    simulator = Simulator(builder.Build())
    simulator.set_target_realtime_rate(1.0)
    return simulator, link.session


def test_the_controller_stops_on_stale_readings_then_ends_when_the_station_is_killed():
    """The fake station in real time, killed 1 s in: the controller's arm reading goes stale
    at once (the robot stops), and 2 s after the last message the run ends with one line
    naming the channel and the URL."""
    url = _udpm_url()
    station = subprocess.Popen(
        [sys.executable, str(FAKE), url, "20", "20", "--realtime"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert station.stdout.readline().strip() == "serving"
        simulator, session = _fake_controller(url, Scenario())
        session.greet()
        simulator.AdvanceTo(1.0)
        station.kill()
        station.wait()
        with pytest.raises(StationLinkError) as stopped:
            simulator.AdvanceTo(30.0)
    finally:
        station.kill()
    line = str(stopped.value)
    assert "\n" not in line
    assert line.startswith(f"the cell station stopped publishing on {url}: nothing on ")
    assert re.search(r"for 2\.\d s \(the limit 2 s\) at t = ", line)
    figures = session.figures()
    assert figures.stale_stops == 1, figures.stale_events
    assert "the robot stops on its path" in figures.stale_events[0]


class _HoldStill(LeafSystem):
    """Commands the arm and the fingers where they are measured."""

    def __init__(self):
        super().__init__()
        arm = self.DeclareVectorInputPort("ur3.state_estimated", 12)
        fingers = self.DeclareVectorInputPort("rg2.state_measured", 2)
        self.DeclareVectorOutputPort(
            "ur3.position", 6, lambda c, o: o.SetFromVector(arm.Eval(c)[:6])
        )
        self.DeclareVectorOutputPort("ur3.velocity", 6, lambda c, o: o.SetFromVector(np.zeros(6)))
        self.DeclareVectorOutputPort(
            "rg2.opening", 1, lambda c, o: o.SetFromVector(fingers.Eval(c)[:1])
        )
        self.DeclareVectorOutputPort("rg2.force", 1, lambda c, o: o.SetFromVector([20.0]))
        self.DeclareAbstractOutputPort(
            "hri.prompt", lambda: AbstractValue.Make(Prompt()), lambda c, o: o.set_value(Prompt())
        )


ROW1 = ["--scenario", "row1-optimal", "--lean"]


# The pace of the pair runs: CI runs another test worker beside the pair's two processes on
# two cores, and at the wall clock's own pace a station starved of CPU fell behind it there
# (the controller then judged the fingers before they had closed; in a loaded local run, an
# arm reading came 0.083 s old against its 0.074 s bound). At half the pace both keep
# their clock; the 100 Hz figures at pace 1 on a quiet machine are the benchmark's
# (`benchmarks/bench_realtime.py`).
PAIR_PACE = "0.5"


def _station(url: str, pace: str | None = None) -> SimulateProcess:
    paced = ["--realtime"] + ([pace] if pace is not None else [])
    station = SimulateProcess(*ROW1, "--lcm", url, *paced, "--json", command="station")
    station.wait_for_line(r"^station row1-optimal: serving on ", timeout=120)
    return station


@pytest.mark.slow
def test_simulate_ends_in_one_line_when_the_station_is_killed():
    """`hrc-drake station --realtime` killed while `hrc-drake simulate --station-lcm
    --realtime` runs row 1: the controller ends with one line naming the channel and the URL,
    exit status 1."""
    url = _udpm_url()
    station = _station(url)
    controller = SimulateProcess(*ROW1, "--station-lcm", url, "--realtime")
    try:
        controller.wait_for_line(r"^cell row1-optimal: sim s", timeout=120)
        station.kill()
        code, out, lines = controller.finish(timeout=60)
    finally:
        station.kill()
        controller.kill()
    assert code == 1 and out == "", lines[-3:]
    assert lines[-1].startswith(
        f"hrc-drake simulate: error: the cell station stopped publishing on {url}: nothing on "
    )
    assert re.search(r"for 2\.\d s \(the limit 2 s\) at t = ", lines[-1])


@pytest.mark.slow
def test_the_station_ends_in_one_line_when_the_controller_is_killed():
    """`hrc-drake station --realtime` and a controller that holds the arm still, which stops
    1 s in without a word: the station's watchdog brakes the arm, and 2 s after the last
    command the station ends with one line naming the channel and the URL, exit status 1."""
    url = _udpm_url()
    station = _station(url, PAIR_PACE)  # at the pair's pace: no stale reading before the kill
    try:
        scenario = load_cell_scenario("row1-optimal", LEAN)
        pace = float(PAIR_PACE)
        link = make_realtime_station_interface(
            scenario, DrakeLcm(url), pace, timeouts=QUICK, identity=ScenarioIdentity.of(scenario)
        )
        builder = DiagramBuilder()
        interface = builder.AddSystem(link.diagram)
        connect_controller(builder, interface, builder.AddSystem(_HoldStill()))
        simulator = Simulator(builder.Build())
        simulator.set_target_realtime_rate(pace)
        link.session.greet()
        simulator.AdvanceTo(1.0)
        # It ran against the station (a stale stop on a starved machine is the link's own
        # answer, and the station's watchdog does not depend on it).
        assert link.session.figures().updates > 0
        code, out, lines = station.finish(timeout=60)  # the controller says nothing more
    finally:
        station.kill()
    assert code == 1 and out == ""
    assert lines[-1].startswith(
        f"hrc-drake station: error: the controller stopped publishing on {url}: nothing on "
    )
    assert re.search(r"for 2\.\d s \(the limit 2 s\) at t = ", lines[-1])
    assert len(lines) == 2  # the hint, then the line


@pytest.mark.slow
def test_a_real_time_pair_runs_row_1():
    """`hrc-drake station --realtime` and `hrc-drake simulate --station-lcm --realtime` in two
    processes: row 1 ends in its states, terminal, with no collision; the station's record
    survives the trip (`faults`, `safety.function`); the JSON's `realtime` has the controller's
    figures (its period near the scenario's, not asserted any closer: no timed asserts)."""
    url = _udpm_url()
    station = _station(url, PAIR_PACE)
    try:
        controller = SimulateProcess(*ROW1, "--station-lcm", url, "--realtime", PAIR_PACE, "--json")
        code, out, lines = controller.finish(timeout=600)
        s_code, s_out, s_lines = station.finish(timeout=60)
    finally:
        station.kill()
    assert code == 0, lines[-5:]
    assert s_code == 0, s_lines[-5:]
    result = json.loads(out)
    assert result["names"] == ["1", "2", "7", "10"] and result["terminal"]
    assert result["collisions"] == 0 and result["error"] is None
    assert result["faults"] == [] and result["safety"]["function"] is not None
    paced = result["realtime"]
    pace = float(PAIR_PACE)
    period = Scenario().run.period / pace  # s of wall time between updates
    assert paced["pace"] == pace and paced["target_period"] == pytest.approx(period)
    assert paced["updates"] > 100 and 0.5 * period < paced["period"] < 2 * period
    assert {"p50", "p99", "max"} <= set(paced["jitter"]) and paced["missed_deadlines"] >= 0
    assert paced["stale_stops"] == len([e for e in paced["stale_events"] if "stops" in e])
    report = json.loads(s_out)
    assert report["scenario"] == "row1-optimal" and report["commands"] > 100
    assert report["realtime"]["pace"] == pace
    assert report["safety_function"] == result["safety"]["function"]


def test_the_station_hint_runs_the_controller_at_the_same_pace():
    """The station's hint gives `--realtime` (and a pace other than 1), for `simulate`."""
    from hrc_drake import cli
    from hrc_drake.cli.station import controller_hint

    for given, pace in ((["--realtime"], 1.0), (["--realtime", "2.5"], 2.5), ([], None)):
        args = cli.build_parser().parse_args(["station", "--lean", *given])
        hint = controller_hint(args, "udpm://239.241.129.94:7667?ttl=0")
        parsed = cli.build_parser().parse_args(shlex.split(hint)[1:])
        assert parsed.realtime == pace and parsed.station_lcm.startswith("udpm://")
