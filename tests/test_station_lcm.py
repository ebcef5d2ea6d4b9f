"""The cell station over LCM (hrc_drake.cell.link.interface, hrc_drake.cell.link.lcm_messages): the
message types, the lockstep against a small fake station (tests/fake_station.py) in one process and
in two, and the errors when the other side is missing."""

from __future__ import annotations

import importlib
import json
import math
import re
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import drake
import numpy as np
import pytest
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, EventStatus

from hrc_drake.cell.controller.build import connect_controller
from hrc_drake.cell.link import lcm_messages as lm
from hrc_drake.cell.link.channels import (
    COMMANDS,
    END_CHANNEL,
    MEASUREMENTS,
    PRE_SUFFIX,
    SIM_CONTACTS,
)
from hrc_drake.cell.link.interface import end_station_session, make_cell_station_interface
from hrc_drake.cell.link.lcm_struct import Field, LcmDecodeError, struct_hash
from hrc_drake.cell.link.lockstep import LockstepTimeouts, StationLinkError, exchange_period
from hrc_drake.cell.link.remote import RemoteCell, run_over_lcm, station_of
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.link.station_record import StationRecord
from hrc_drake.cell.link.station_server import CellStationServer, cell_station_hooks
from hrc_drake.cell.ports import (
    BodySpheres,
    CellConfiguration,
    PartPlacement,
    PartStatus,
    SafetyMode,
    placement_transform,
    pose_tuple,
)
from hrc_drake.cell.run.loop import ClosedLoop
from hrc_drake.cell.run.run import build_closed_loop, controller_of, run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario, plant_step
from hrc_drake.cell.station.contacts import Owner, geometry_owners, owner_pairs
from hrc_drake.cell.station.faults import Injection
from hrc_drake.cell.station.safety_function import SafetyFunctionLog
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.scenario.schema import Scenario, ScenarioError

sys.path.insert(0, str(Path(__file__).parent))
from fake_station import (
    CONFIGURATION,
    STEP,
    FakeController,
    make_fake_station,
)

FAKE = Path(__file__).parent / "fake_station.py"
DURATION = 0.4  # s of simulated time: 40 exchanges (10 ms plant steps), 20 controller updates
QUICK = LockstepTimeouts(start=3.0, step=3.0, resend=0.2)


def _udpm_url() -> str:
    """A host-local multicast URL on a port no one here uses now (tests may run in parallel)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return f"udpm://239.241.129.92:{port}?ttl=0"


# --- messages --------------------------------------------------------------------------------
LCM_PRIMITIVES = {"int8_t", "int16_t", "int32_t", "int64_t", "byte", "float", "double", "string"}
LCM_PRIMITIVES |= {"boolean"}


def _drake_fields(cls) -> list[Field]:
    """The members of one of Drake's lcm-gen classes (a struct member's type as a class)."""
    return [
        Field(
            kind if kind in LCM_PRIMITIVES else object,
            name,
            tuple(int(d) if str(d).isdigit() else d for d in dims or ()),
        )
        for name, kind, dims in zip(
            cls.__slots__, cls.__typenames__, cls.__dimensions__, strict=True
        )
    ]


def test_struct_hash_is_lcm_gens_for_every_drake_type():
    """Our fingerprints are lcm-gen's: the struct hash of each of Drake's generated types,
    computed from its member list, is the constant lcm-gen wrote into it."""
    names = [n for n in dir(drake) if n.startswith("lcmt_")]
    assert len(names) > 30
    for name in names:
        source = Path(importlib.import_module(f"drake.{name}").__file__).read_text()
        written = int(re.search(r"tmphash = \(\(?(0x[0-9a-f]+)", source).group(1), 16)
        assert struct_hash(_drake_fields(getattr(drake, name))) == written, name


# The fake station's configuration and a part that fell on the table, tilted: every pose bit.
DROPPED = CellConfiguration(
    (
        *CONFIGURATION.placements,
        (
            "oval_flange_3",
            PartPlacement(
                PartStatus.TRANSIT,
                pose=pose_tuple(RigidTransform(RollPitchYaw(0.4, -1.1, 2.9), [0.61, 0.37, 0.0089])),
            ),
        ),
    )
)


def _examples() -> dict[str, tuple]:
    """Port values for every channel, unlike the defaults."""
    body = BodySpheres(
        np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6], [0.7, 0.8, 0.9]]),
        np.array([0.05, 0.04, 0.1]),
        np.array([[1.0, 0.0, -1.0], [0.5, 0.25, 0.125], [0.0, 0.0, 0.0]]),
        ((0, 2), (2, 3)),
    )
    return {
        "UR3_COMMAND": (np.linspace(-1, 1, 6) / 3, np.linspace(2, 3, 6) / 7),
        "RG2_COMMAND": (np.array([0.0451]), np.array([17.5])),
        "HRI_PROMPT": (Prompt(3, PromptKind.BOLT, ("F1", "S12"), "F3", "oval_flange_2"),),
        "UR3_STATUS": (np.linspace(-3, 3, 12) / 11, np.array([1.0]), np.array([5.0])),
        "UR3_TCP_FORCE": (np.array([0.25, -1.5, 7.125, 0.01, -0.02, 1 / 3]),),
        "RG2_STATUS": (np.array([0.0449, -0.0021]), np.array([1.0])),
        "CELL_CONFIGURATION": (DROPPED,),
        "OPERATOR_BODY": (body,),
        "HRI_INDICATION": (Indication(2, "S12", True, 7.125),),
        "SIM_CONTACTS": (
            (
                (Owner("rg2", "left_finger"), Owner("oval_flange_1", "oval_flange_1")),
                (Owner("tray", "tray"), Owner("square_flange", "square_flange")),
            ),
        ),
    }


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, BodySpheres):
        arrays = ("centres", "radii", "velocities")
        return all(_same(getattr(a, k), getattr(b, k)) for k in arrays) and a.groups == b.groups
    return a == b


@pytest.mark.parametrize("channel", [*COMMANDS, *MEASUREMENTS, SIM_CONTACTS])
def test_every_message_round_trips(channel):
    """Port values -> message -> LCM bytes -> message -> port values, bit for bit; and the
    message bytes' stamp is read without decoding."""
    values = _examples()[channel.channel]
    message = channel.encode(123_456, *values)
    data = message.encode()
    decoded = channel.message.decode(data)
    assert decoded.encode() == data
    assert channel.stamp_of(data) == 123_456
    back = channel.decode(decoded)
    assert len(back) == len(values)
    assert all(_same(a, b) for a, b in zip(values, back, strict=True)), (values, back)


def test_configuration_poses_arrive_bit_for_bit():
    """A measured pose arrives as the very doubles sent; a placement without one (the
    operator's confirmation) says so with `has_pose` and arrives without one."""
    message = lm.configuration_message(0, DROPPED)
    flags = {p.instance: p.has_pose for p in message.placements}
    assert flags == {
        "oval_flange_1": True,
        "square_flange": False,
        "oval_flange_2": True,
        "oval_flange_3": True,
    }
    (back,) = lm.configuration_value(lm.lcmt_cell_configuration.decode(message.encode()))
    for (name, sent), (_, got) in zip(DROPPED.placements, back.placements, strict=True):
        assert struct.pack(f">{len(sent.pose)}d", *sent.pose) == struct.pack(
            f">{len(got.pose)}d", *got.pose
        ), name
    assert back.placement("square_flange").pose == ()
    X = placement_transform(back.placement("oval_flange_3"))
    assert X.IsNearlyEqualTo(
        RigidTransform(RollPitchYaw(0.4, -1.1, 2.9), [0.61, 0.37, 0.0089]), 1e-15
    )
    bad = CellConfiguration(
        (("oval_flange_1", PartPlacement(PartStatus.TRANSIT, pose=(1.0,) * 3)),)
    )
    with pytest.raises(ValueError, match="oval_flange_1 has a pose of 3 values; a pose is 7"):
        lm.configuration_message(0, bad)


def test_defaults_and_session_round_trip():
    """Empty values (a prompt of nothing, no body, no task yet) and session messages too."""
    assert lm.prompt_value(lm.lcmt_hri_prompt.decode(lm.prompt_message(0, Prompt()).encode())) == (
        Prompt(),
    )
    nobody = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
    (back,) = lm.body_value(lm.lcmt_operator_body.decode(lm.body_message(0, nobody).encode()))
    assert back.centres.shape == (0, 3) and back.groups == ()
    message = lm.indication_message(5, Indication())
    assert lm.indication_value(lm.lcmt_hri_indication.decode(message.encode())) == (Indication(),)
    report = lm.session_message(7, "report", {"sim_time": 1.5})
    assert lm.lcmt_station_session.decode(report.encode()) == report


def test_station_record_round_trips_through_the_report():
    """The fault record and the safety function's log, as JSON in the station's report, come
    back as the same values; a report without them (a station that keeps none) has none, and
    one that cannot be read stops the run with one line."""
    record = StationRecord(
        (
            Injection("no-path", 2, 3.07, 3.07, None, 4.1, False, (0.41, -0.2, 0.013)),
            Injection("grip-lost", 1, 1.0, 2.5300000000000002, 2.01, None, True),
            Injection("pushed", 3),
        ),
        SafetyFunctionLog(1, 2, 2, 10.5, 0.25, 0.125, ("1.00: protective stop: external input",)),
    )
    text = lm.session_message(5, "report", {"sim_time": 9.0, "exchanges": 900, **record.to_json()})
    report = json.loads(lm.lcmt_station_session.decode(text.encode()).text)
    assert StationRecord.from_report(report) == record
    bare = {"sim_time": 9.0, "exchanges": 900}
    assert StationRecord.from_report(bare) is None
    assert StationRecord.from_report({**bare, **StationRecord().to_json()}) == StationRecord()
    # A camera's score rides along (only with a camera: the key is absent without one).
    assert "camera" not in record.to_json()
    camera = StationRecord(camera={"frames": 3, "false_detections": 0, "events": []})
    assert StationRecord.from_report({**bare, **camera.to_json()}) == camera
    report["injected"][0]["colour"] = "red"
    with pytest.raises(StationLinkError, match="the cell station's report has a fault record"):
        StationRecord.from_report(report)


def test_ur3_status_leaves_what_a_simulation_does_not_measure_unknown():
    status = lm.ur3_status(1, np.arange(12.0), [0.0], [1.0])
    assert all(math.isnan(x) for x in status.joint_torque + status.joint_position_desired)
    assert status.num_joints == 6 and status.joint_velocity == list(np.arange(6.0, 12.0))
    assert lm.ur3_status_values(status)[1][0] == 0.0
    # Each safety mode is a robot mode, and back; a stop says it is one.
    for mode, robot_mode, stop in (
        (SafetyMode.NORMAL, lm.lcmt_panda_status.kMove, 0.0),
        (SafetyMode.REDUCED, lm.lcmt_panda_status.kOther, 0.0),
        (SafetyMode.PROTECTIVE_STOP, lm.lcmt_panda_status.kReflex, 1.0),
        (SafetyMode.SAFEGUARD_STOP, lm.lcmt_panda_status.kUserStopped, 1.0),
    ):
        message = lm.ur3_status(1, np.arange(12.0), [stop], [float(mode)])
        decoded = lm.lcmt_panda_status.decode(message.encode())
        assert decoded.robot_mode == robot_mode
        _, stopped, back = lm.ur3_status_values(decoded)
        assert stopped[0] == stop and SafetyMode(int(back[0])) == mode
    with pytest.raises(ValueError, match=r"safety\.mode 4\.0 is not a safety mode"):
        lm.ur3_status(1, np.arange(12.0), [0.0], [4.0])


def test_decode_errors_name_the_type():
    prompt = lm.prompt_message(1, Prompt()).encode()
    with pytest.raises(LcmDecodeError, match="not a lcmt_hri_indication message"):
        lm.lcmt_hri_indication.decode(prompt)
    with pytest.raises(LcmDecodeError, match="truncated"):
        lm.lcmt_hri_prompt.decode(prompt[:-3])
    with pytest.raises(LcmDecodeError, match="HRI_INDICATION: not a lcmt_hri_indication"):
        MEASUREMENTS[-1].stamp_of(prompt)
    short = lm.lcmt_panda_status()
    short.num_joints, short.joint_position, short.joint_velocity = 0, [], []
    with pytest.raises(LcmDecodeError, match="UR3 status positions: 0 values where 6"):
        lm.ur3_status_values(short)


def test_definitions_are_lcm_syntax_of_the_classes():
    """The .lcm text docs/hardware.md shows declares exactly the members the classes encode."""
    text = lm.lcm_definitions()
    for cls in (lm.lcmt_rg2_status, lm.lcmt_operator_body, lm.lcmt_cell_configuration):
        for line in cls.definition().splitlines()[1:-1]:
            assert line.strip() in text, line


def test_exchange_period_needs_whole_plant_steps():
    assert exchange_period(Scenario()) == plant_step(Scenario()) == 0.01
    scenario = Scenario()
    scenario.run.period = 0.025
    with pytest.raises(ScenarioError, match=r"run.period 0.025 s is not a whole number"):
        exchange_period(scenario)


# --- the lockstep, one process ----------------------------------------------------------------
def _run_direct(duration: float = DURATION):
    builder = DiagramBuilder()
    station = builder.AddSystem(make_fake_station())
    controller = builder.AddSystem(FakeController())
    connect_controller(builder, station, controller)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    context = station.GetMyContextFromRoot(simulator.get_context())
    return controller.log, station.GetOutputPort("ur3.state_estimated").Eval(context)


def _run_controller(lcm: DrakeLcm, duration: float = DURATION, timeouts=QUICK, monitor=None):
    """The fake controller against a station interface on `lcm`; (log, session report)."""
    builder = DiagramBuilder()
    interface = builder.AddSystem(make_cell_station_interface(Scenario(), lcm, timeouts=timeouts))
    controller = builder.AddSystem(FakeController())
    connect_controller(builder, interface, controller)
    simulator = Simulator(builder.Build())
    if monitor is not None:
        simulator.set_monitor(monitor)
    simulator.AdvanceTo(duration)
    return controller.log, end_station_session(interface, timeout=3.0)


def test_fake_station_over_memq_equals_direct():
    """The same controller reads exactly the same measurements, and the station ends in
    exactly the same state, over LCM as in one diagram: the grip sensor's feedthrough of the
    commanded opening and the operator's update read the commands as they stood before the
    controller's update; the servo reads them after it."""
    direct_log, direct_state = _run_direct()
    lcm = DrakeLcm("memq://")
    station = make_fake_station()
    server = CellStationServer(station, lcm, STEP, timeouts=QUICK)
    log, report = _run_controller(lcm)
    assert report == {"sim_time": DURATION, "exchanges": round(DURATION / STEP)}
    assert server.report == report and server.error is None
    assert len(log) == len(direct_log) == 20
    assert repr(log) == repr(direct_log)
    # The run exercised what the order matters for: a grip detected, prompts answered.
    assert {entry[3] for entry in log} == {0.0, 1.0}
    assert log[-1][-1].step >= 3
    state = station.GetOutputPort("ur3.state_estimated").Eval(
        station.GetMyContextFromRoot(server.root_context)
    )
    assert np.array_equal(state, direct_state)


def test_station_error_reaches_the_controller():
    """A station that fails sends its error; the controller's run ends with it."""
    lcm = DrakeLcm("memq://")
    server = CellStationServer(make_fake_station(fail_at=0.1), lcm, STEP, timeouts=QUICK)
    with pytest.raises(StationLinkError, match=r"the fake station broke at t = 0\.100 s"):
        _run_controller(lcm)
    assert isinstance(server.error, RuntimeError)


def test_repeated_commands_are_answered_again():
    """A lost datagram: the controller sends its last commands again, the station answers
    with the same measurements (and does not step twice)."""
    lcm = DrakeLcm("memq://")
    server = CellStationServer(make_fake_station(), lcm, STEP, timeouts=QUICK)
    heard = []
    lcm.Subscribe("UR3_STATUS", heard.append)
    # The session's hello first (a controller that states no scenario): then the lockstep.
    lcm.Publish(END_CHANNEL, lm.session_message(0, "hello", "{}").encode())
    commands = [
        (c.channel, c.encode(0, *(np.zeros(p.size) if p.size else p.model() for p in c.ports)))
        for c in COMMANDS
    ]
    for _ in range(2):
        for channel, message in commands:
            lcm.Publish(channel + PRE_SUFFIX, message.encode())
        lcm.HandleSubscriptions(0)
        lcm.HandleSubscriptions(0)
    assert len(heard) == 2 and heard[0] == heard[1]
    assert server.root_context.get_time() == 0.0 and server.error is None


def test_controller_without_a_station_times_out():
    lcm = DrakeLcm(_udpm_url())
    quick = LockstepTimeouts(start=0.5, step=0.5, resend=0.1)
    start = time.monotonic()
    with pytest.raises(StationLinkError, match=r"no cell station answered on udpm://.* within"):
        _run_controller(lcm, timeouts=quick)
    assert time.monotonic() - start < 5.0


# --- two processes ----------------------------------------------------------------------------
def _serve_fake(url: str, start: float = 30.0, step: float = 30.0) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, str(FAKE), url, str(start), str(step)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout.readline().strip() == "serving"
    return process


def test_two_processes_equal_one_diagram():
    """The fake station in another process over UDP multicast: the controller reads what it
    reads in one diagram, and the station ends in the same state."""
    url = _udpm_url()
    process = _serve_fake(url)
    try:
        log, report = _run_controller(DrakeLcm(url))
        out, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, err
    direct_log, direct_state = _run_direct()
    assert report["exchanges"] == round(DURATION / STEP)
    assert repr(log) == repr(direct_log)
    words = out.split("report", 1)[1].split()
    assert int(words[0]) == report["exchanges"]
    assert [float(x) for x in words[1:]] == list(direct_state)


def test_station_without_a_controller_times_out():
    process = _serve_fake(_udpm_url(), start=0.5, step=0.5)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 1
    assert re.search(r"no controller came on udpm://\S+ within 0.5 s", err), err


def test_controller_reports_a_station_that_dies():
    url = _udpm_url()
    process = _serve_fake(url)
    quick = LockstepTimeouts(start=5.0, step=1.0, resend=0.2)

    def kill_at_a_tenth(context):
        if context.get_time() >= 0.1 and process.poll() is None:
            process.kill()
            process.wait()
        return EventStatus.DidNothing()

    try:
        with pytest.raises(StationLinkError, match="the cell station stopped answering on udpm"):
            _run_controller(DrakeLcm(url), timeouts=quick, monitor=kill_at_a_tenth)
    finally:
        process.kill()


# --- the cell's own station ------------------------------------------------------------------
def _plant_positions(station, root) -> np.ndarray:
    return station.plant.GetPositions(station.plant.GetMyContextFromRoot(root))


@pytest.mark.slow
def test_cell_station_over_memq_equals_one_diagram():
    """The cell's station and controller over LCM in one process, against the one-diagram run:
    while the first part is held (3.5 s: by the fingers' friction; the robot started on it at
    once) and after it is let go (6.5 s),
    the plant's state, the touching pairs the collision watch reads and the Supervisor's events
    are the same, bit for bit."""
    scenario = load_cell_scenario("row1-optimal", LEAN)
    loop = build_closed_loop(scenario)
    station = station_of(scenario)
    lcm = DrakeLcm("memq://")
    period = exchange_period(scenario)
    server = CellStationServer(station.diagram, lcm, period, cell_station_hooks(station))
    setup = loop.setup
    interface = make_cell_station_interface(setup.scenario, lcm, timeouts=QUICK, sim_contacts=True)
    remote = ClosedLoop(setup, RemoteCell(interface), controller_of(setup))
    owners = geometry_owners(loop.station.plant)
    for t, held in ((3.5, True), (6.5, False)):
        loop.advance_to(t)
        remote.simulator.AdvanceTo(t)
        assert np.array_equal(
            _plant_positions(station, server.root_context),
            _plant_positions(loop.station, loop.root_context),
        )
        results = loop.station.diagram.GetOutputPort("sim.contact_results").Eval(
            loop.station.diagram.GetMyContextFromRoot(loop.root_context)
        )
        touching = remote.cell.touching(remote.simulator.get_context())
        assert touching == tuple(owner_pairs(results, owners))
        assert any(a.model == "rg2" or b.model == "rg2" for a, b in touching) == held
        assert remote.status.events == loop.status.events
        assert repr(remote.status.history) == repr(loop.status.history)


# A protective stop 1 s into task 1: the station's injector and safety function both act.
STOP = "{faults: [!ProtectiveStop {task: 1, after: 1.0, duration: 0.5}]}"


@pytest.mark.slow
def test_cell_station_in_another_process_equals_one_process(tmp_path):
    """`hrc-drake station` in one process, the controller in this one, row 1 with a protective
    stop: the same states, terminal, final configuration, collisions and simulated time as the
    one-process run, and the station's fault record and safety function's log, which only the
    station keeps, reach the run's JSON (`faults`, `safety.function`) as in one process."""
    url = _udpm_url()
    station = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "hrc_drake.cli",
            "station",
            "--scenario",
            "row1-optimal",
            "--lean",
            "--scenario-text",
            STOP,
            "--lcm",
            url,
            "--json",
            "--timeout",
            "120",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    scenario = load_cell_scenario("row1-optimal", [LEAN, STOP])
    identity = ScenarioIdentity.of(scenario, ["--lean", "--scenario-text", STOP])
    try:
        remote = run_over_lcm(scenario, url, identity=identity)
        out, err = station.communicate(timeout=60)
    finally:
        station.kill()
    assert station.returncode == 0, err
    here = run_scenario(scenario)
    assert here.done and remote.done
    assert remote.states == here.states
    assert remote.final_tokens == here.final_tokens
    assert remote.collisions == here.collisions
    assert remote.sim_time == here.sim_time
    assert remote.events == here.events
    ours, theirs = here.to_json(), remote.to_json()
    (fault,) = ours["faults"]
    assert fault["injected_at"] is not None and fault["recovery"] == "resume", fault
    assert theirs["faults"] == ours["faults"]
    function = ours["safety"]["function"]
    assert (function["protective_stops"], function["unlocks"]) == (1, 1), function
    assert theirs["safety"]["function"] == function
    report = json.loads(out)
    assert report["sim_time"] == pytest.approx(here.sim_time)
    assert report["safety_function"] == function


def test_station_command_without_a_controller_ends_with_one_line():
    """`hrc-drake station` that no controller comes to: one line, exit status 1."""
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "hrc_drake.cli",
            "station",
            "--scenario",
            "row1-optimal",
            "--lcm",
            _udpm_url(),
            "--timeout",
            "1",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("station row1-optimal: serving on udpm://")
    assert re.fullmatch(
        r"hrc-drake station: error: no controller came on udpm://\S+ within 1 s: "
        r"run `hrc-drake simulate --scenario S --station-lcm \S+`",
        lines[-1],
    )


def test_simulate_over_lcm_refuses_what_needs_the_station_here(tmp_path):
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "hrc_drake.cli",
            "simulate",
            "--lean",
            "--station-lcm",
            _udpm_url(),
            "--record",
            str(tmp_path / "run.html"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert "--station-lcm runs only the controller here" in result.stderr
    assert not (tmp_path / "run.html").exists()


def test_hardware_doc_shows_the_definitions_the_classes_are_made_from():
    doc = (Path(__file__).parents[1] / "docs" / "hardware.md").read_text()
    assert lm.lcm_definitions() in doc
    for channel in (*COMMANDS, *MEASUREMENTS, SIM_CONTACTS):
        assert f"`{channel.channel}`" in doc


@pytest.mark.parametrize(
    "argv",
    [
        ["station", "--lcm", "udpm://10.1.2.3:7667"],
        ["station", "--timeout", "0"],
        ["simulate", "--lean", "--station-lcm", "memq://"],
    ],
)
def test_bad_link_options_are_refused_in_one_line(argv):
    result = subprocess.run(
        [sys.executable, "-m", "hrc_drake.cli", *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"hrc-drake {argv[0]}: error: --")
