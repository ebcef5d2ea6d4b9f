"""The RG2 driver over Modbus TCP (hrc_drake.drivers.rg2_modbus) end to end against a Modbus
server on the loopback driven by the station's simulated gripper (tests/rg2_sim_device.py): the
registers and their units, the opening converging, the grip on an object, refused targets, a
missing server, and the LCM bridge serving RG2_COMMAND and RG2_STATUS."""

from __future__ import annotations

import itertools
import math
import socket
import sys
import threading
import time
from pathlib import Path

import pytest
from pydrake.lcm import DrakeLcm

from hrc_drake.cell.link import lcm_messages as lm
from hrc_drake.drivers.rg2_modbus import (
    ACTUAL_WIDTH,
    GRIP,
    TARGET_FORCE,
    Rg2ConnectionError,
    Rg2LcmBridge,
    Rg2Modbus,
    Rg2Reading,
    Rg2Settings,
    main,
)
from hrc_drake.robot_models import RG2_MAX_FORCE, RG2_MAX_OPENING, RG2_MIN_FORCE

sys.path.insert(0, str(Path(__file__).parent))
from rg2_sim_device import Rg2ModbusServer, SimulatedRg2, free_port

BLOCK = 0.045  # m, the object the fingers close on
POLL = 0.02  # s between the tests' readings
TOLERANCE = 0.0002  # m: two register counts


@pytest.fixture(scope="module")
def free_rg2():
    with Rg2ModbusServer(SimulatedRg2()) as server:
        yield server


@pytest.fixture(scope="module")
def blocked_rg2():
    with Rg2ModbusServer(SimulatedRg2(block_width=BLOCK)) as server:
        yield server


def _driver(server: Rg2ModbusServer, **settings) -> Rg2Modbus:
    driver = Rg2Modbus(Rg2Settings("127.0.0.1", port=server.port, timeout=0.5, **settings))
    driver.connect()
    return driver


def _poll_until(driver: Rg2Modbus, done, polls: int = 150) -> list[Rg2Reading]:
    """Readings every POLL until `done(reading)` (or `polls` of them)."""
    readings = [driver.read()]
    while not done(readings[-1]) and len(readings) < polls:
        time.sleep(POLL)
        readings.append(driver.read())
    return readings


def test_a_target_reaches_the_registers_in_their_units(free_rg2):
    """Opening [m] -> 1/10 mm in register 1, force [N] -> 1/10 N in register 0, grip in 2; the
    simulated gripper takes them back in metres and newtons."""
    driver = _driver(free_rg2)
    try:
        assert driver.command(0.04523, 12.34)
        assert free_rg2.registers(TARGET_FORCE, 3) == [123, 452, GRIP]
        _poll_until(driver, lambda r: free_rg2.targets[-1] == (0.0452, 12.3), polls=20)
        assert free_rg2.targets[-1] == (0.0452, 12.3)
    finally:
        driver.close()


def test_a_ramp_sends_only_steps_over_a_millimetre_and_its_end(free_rg2):
    """docs/hardware.md's rule: a target goes out when it differs from the last sent by more
    than 1 mm or its force changed; the ramp's end once it is commanded twice."""
    driver = _driver(free_rg2)
    try:
        ramp = [0.0600 - 0.0002 * i for i in range(26)]  # 60 mm to 55 mm by 0.2 mm
        sent = [driver.command(opening, 20.0) for opening in ramp]
        widths = [ramp[i] for i, s in enumerate(sent) if s]
        assert widths == pytest.approx([0.0600, 0.0588, 0.0576, 0.0564, 0.0552])
        assert free_rg2.registers(TARGET_FORCE, 3) == [200, 552, GRIP]
        assert driver.command(ramp[-1], 20.0)  # held: the ramp's end, 55.0 mm
        assert free_rg2.registers(TARGET_FORCE, 3) == [200, 550, GRIP]
        assert not driver.command(ramp[-1], 20.0)
        assert driver.command(ramp[-1], 25.0)  # a new force goes at once
        assert free_rg2.registers(TARGET_FORCE, 3) == [250, 550, GRIP]
    finally:
        driver.close()


def test_the_opening_read_back_converges_to_the_command(free_rg2):
    driver = _driver(free_rg2)
    try:
        for target in (0.030, 0.080):
            driver.command(target, 20.0)
            readings = _poll_until(
                driver, lambda r, t=target: abs(r.opening - t) < TOLERANCE and not r.busy
            )
            last = readings[-1]
            assert last.opening == pytest.approx(target, abs=TOLERANCE)
            assert not last.busy and not last.grip_detected
            # the rate is the difference of successive readings over their time
            for before, after in itertools.pairwise(readings):
                slope = (after.opening - before.opening) / (after.time - before.time)
                assert after.opening_rate == pytest.approx(slope)
            moving = [r.opening_rate for r in readings]
            assert (min(moving) < -0.01) if target == 0.030 else (max(moving) > 0.01)
    finally:
        driver.close()


def test_closing_on_an_object_detects_the_grip(blocked_rg2):
    driver = _driver(blocked_rg2)
    try:
        driver.command(0.0, 20.0)
        readings = _poll_until(driver, lambda r: r.grip_detected and not r.busy)
        assert readings[-1].grip_detected and not readings[-1].busy
        assert readings[-1].opening == pytest.approx(BLOCK, abs=0.0005)
        driver.command(0.070, 20.0)  # opening again lets go
        readings = _poll_until(driver, lambda r: abs(r.opening - 0.070) < TOLERANCE)
        assert readings[-1].opening == pytest.approx(0.070, abs=TOLERANCE)
        assert not readings[-1].grip_detected
    finally:
        driver.close()


@pytest.mark.parametrize(
    ("opening", "force", "message"),
    [
        (RG2_MAX_OPENING + 0.001, 20.0, "outside its stroke"),
        (-0.001, 20.0, "outside its stroke"),
        (0.05, RG2_MIN_FORCE - 0.1, "outside its range"),
        (0.05, RG2_MAX_FORCE + 0.1, "outside its range"),
        (math.nan, 20.0, "not a number"),
    ],
)
def test_a_target_the_rg2_cannot_take_is_refused(free_rg2, opening, force, message):
    driver = _driver(free_rg2)
    try:
        driver.command(0.05, 20.0)
        with pytest.raises(ValueError, match=message):
            driver.command(opening, force)
        assert free_rg2.registers(TARGET_FORCE, 3) == [200, 500, GRIP]
        assert driver.sent is not None and (driver.sent.force, driver.sent.width) == (200, 500)
    finally:
        driver.close()


def test_the_stroke_and_force_limits_themselves_are_taken(free_rg2):
    driver = _driver(free_rg2)
    try:
        assert driver.command(RG2_MAX_OPENING, RG2_MAX_FORCE)
        assert free_rg2.registers(TARGET_FORCE, 3) == [400, 1100, GRIP]
        assert driver.command(0.0, RG2_MIN_FORCE)
        assert free_rg2.registers(TARGET_FORCE, 3) == [30, 0, GRIP]
    finally:
        driver.close()


def test_no_server_gives_a_clear_error():
    port = free_port()
    driver = Rg2Modbus(Rg2Settings("127.0.0.1", port=port, timeout=0.2))
    with pytest.raises(Rg2ConnectionError, match=rf"127\.0\.0\.1:{port} .*Compute Box"):
        driver.connect()


def test_a_server_without_the_rg2_unit_gives_a_clear_error(free_rg2):
    driver = Rg2Modbus(Rg2Settings("127.0.0.1", port=free_rg2.port, unit=66, timeout=0.3))
    with pytest.raises(Rg2ConnectionError, match=r"does not serve an RG2 as unit 66"):
        driver.connect()


def _udpm_url() -> str:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    return f"udpm://239.241.129.92:{port}?ttl=0"


def _handle_for(lcm: DrakeLcm, duration: float) -> None:
    """Handle LCM for `duration` [s] without blocking in pydrake, which would hold the GIL
    and stall the bridge's thread."""
    lcm.HandleSubscriptions(0)
    time.sleep(duration)
    lcm.HandleSubscriptions(0)


def test_the_lcm_bridge_serves_rg2_command_and_rg2_status(free_rg2):
    """An RG2_COMMAND published on LCM becomes register writes; RG2_STATUS comes back at the
    poll rate, stamped with the host's clock, and converges to the command; a command out of
    range is refused and the gripper keeps its target."""
    url = _udpm_url()
    driver = _driver(free_rg2, poll_rate=50.0)
    bridge = Rg2LcmBridge(driver, DrakeLcm(url))
    stop = threading.Event()
    thread = threading.Thread(target=bridge.run, args=(stop,), daemon=True)
    controller = DrakeLcm(url)
    statuses = []
    controller.Subscribe(
        "RG2_STATUS", lambda data: statuses.append(lm.lcmt_rg2_status.decode(data))
    )
    thread.start()
    try:
        for _ in range(150):
            command = lm.rg2_command(lm.utime(time.time()), [0.0612], [15.0])
            controller.Publish("RG2_COMMAND", command.encode())
            _handle_for(controller, POLL)
            if statuses and statuses[-1].opening == 0.0612 and statuses[-1].opening_rate == 0:
                break  # settled on the target
        assert free_rg2.registers(TARGET_FORCE, 3) == [150, 612, GRIP]
        assert statuses[-1].opening == 0.0612 and statuses[-1].opening_rate == 0
        assert free_rg2.registers(ACTUAL_WIDTH, 1) == [612]
        assert not statuses[-1].grip_detected
        stamps = [s.utime for s in statuses]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        assert abs(stamps[-1] / 1e6 - time.time()) < 60  # the host's clock, not station time
        wide = lm.rg2_command(lm.utime(time.time()), [0.2], [15.0])
        for _ in range(50):
            controller.Publish("RG2_COMMAND", wide.encode())
            _handle_for(controller, POLL)
            if bridge.refused:
                break
        assert bridge.refused and "outside its stroke" in bridge.refused[-1]
        assert free_rg2.registers(TARGET_FORCE, 3) == [150, 612, GRIP]
    finally:
        stop.set()
        thread.join(timeout=5)
        driver.close()
    assert not thread.is_alive()
    assert bridge.commands > 0 and bridge.published >= len(statuses)


def test_the_drivers_import_nothing_of_the_simulated_station():
    """The drivers are the real devices' side of the ports: none of their modules reaches the
    simulated station directly (what they import of the link is the ports' messages)."""
    from test_import_cycles import import_graph

    graph = import_graph()
    drivers = [n for n in graph if n.startswith("hrc_drake.drivers.")]
    assert "hrc_drake.drivers.rg2_modbus" in drivers
    direct = [(a, b) for a in drivers for b in graph.successors(a)]
    assert [(a, b) for a, b in direct if b.startswith("hrc_drake.cell.station")] == []


def test_the_bridge_command_says_in_one_line_when_no_rg2_answers(capsys):
    """`python -m hrc_drake.drivers.rg2_modbus` (its `main`) with nothing at the address: exit
    status 1 and one line naming host:port."""
    port = free_port()
    options = ["--host", "127.0.0.1", "--port", str(port), "--timeout", "0.2"]
    assert main([*options, "--lcm", _udpm_url()]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0], lines
    assert lines[0].startswith("python -m hrc_drake.drivers.rg2_modbus: error: ")


def test_a_driver_connected_again_sends_its_next_target(free_rg2):
    driver = _driver(free_rg2)
    try:
        assert driver.command(0.05, 20.0)
        assert not driver.command(0.0505, 20.0)
        driver.close()
        driver.connect()
        assert driver.command(0.0505, 20.0)
        assert free_rg2.registers(TARGET_FORCE, 3) == [200, 505, GRIP]
    finally:
        driver.close()
