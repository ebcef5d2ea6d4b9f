"""Issue 31, item 4, drivers as data: the scenario's `drivers:` section says what stands behind
each device port (`!Simulated {}`, `!UrRtde {...}`, `!Rg2Modbus {...}`), read alike by our loader
and Drake's, its errors one line; `hrc-drake drivers` serves the devices put on real hardware
(here the RG2 over the loopback Modbus server of tests/rg2_sim_device.py) and `hrc-drake
station` refuses such a scenario."""

from __future__ import annotations

import dataclasses
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.lcm import DrakeLcm

from hrc_drake.cell.link import lcm_messages as lm
from hrc_drake.drivers.settings import Rg2Settings, Ur3RtdeSettings
from hrc_drake.scenario.drivers import DriversConfig, Rg2Modbus, Simulated, UrRtde
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import Scenario, ScenarioError

sys.path.insert(0, str(Path(__file__).parent))
from rg2_sim_device import Rg2ModbusServer, SimulatedRg2, free_port
from test_careless_inputs import refused
from test_rg2_modbus import _udpm_url
from test_ur3_rtde import HOME, FakeControl, FakeReceive

REAL = (
    "{drivers: {ur3: !UrRtde {host: 10.0.0.2, frequency: 500, gain: 600}, "
    "rg2: !Rg2Modbus {host: box, unit: 66}}}"
)


def _rg2_text(port: int, **more) -> str:
    values = ", ".join(f"{k}: {v}" for k, v in {"port": port, **more}.items())
    return f"{{drivers: {{rg2: !Rg2Modbus {{host: 127.0.0.1, {values}}}}}}}"


def test_devices_are_simulated_unless_the_scenario_says_otherwise():
    assert load_scenario("row1-optimal").drivers == DriversConfig(Simulated(), Simulated())
    assert DriversConfig().on_hardware() == {}


def test_real_drivers_take_their_settings_defaults_from_the_drivers():
    drivers = load_scenario("row1-optimal", REAL).drivers
    assert list(drivers.on_hardware()) == ["ur3", "rg2"]
    assert drivers.ur3.settings() == dataclasses.replace(
        Ur3RtdeSettings.e_series("10.0.0.2"), gain=600.0
    )
    assert drivers.rg2.settings() == Rg2Settings("box", unit=66)
    # Left out, a value is the driver's own default (stated once, in hrc_drake.drivers.settings).
    assert UrRtde(host="h").settings() == Ur3RtdeSettings.e_series("h")
    assert Rg2Modbus(host="h").settings() == Rg2Settings("h")


@pytest.mark.parametrize("text", [REAL, "{drivers: {rg2: !Simulated {}}}", "{}"])
def test_drake_loads_the_same_drivers(text):
    ours = load_scenario(None, text).drivers
    drakes = yaml_load_typed(schema=Scenario, data=text, defaults=Scenario()).drivers
    assert ours == drakes and type(ours.ur3) is type(drakes.ur3)


@pytest.mark.parametrize(
    ("drivers", "words"),
    [
        ("{rg2: !Rg2Modbus {host: a, prot: 5}}", ["drivers.rg2.prot: unknown key", "'port'"]),
        ("{ur3: !Rg2Modbus {host: a}}", ["drivers.ur3: unknown tag !Rg2Modbus", "!UrRtde"]),
        ("{rg2: !Simulatd {}}", ["did you mean !Simulated?"]),
        ("{rg2: {host: a}}", ["drivers.rg2: untagged", "!Rg2Modbus"]),
        ("{gripper: !Simulated {}}", ["drivers.gripper: unknown key", "['rg2', 'ur3']"]),
        ("{ur3: !UrRtde {}}", ["drivers.ur3: host is empty"]),
        ("{ur3: !UrRtde {host: a, frequency: 250}}", ["250 Hz is not RTDE's", "125 (CB3)"]),
        ("{ur3: !UrRtde {host: a, lookahead_time: 0.5}}", ["drivers.ur3: lookahead_time 0.5"]),
        ("{rg2: !Rg2Modbus {host: a, port: 70000}}", ["drivers.rg2: RG2 port 70000"]),
        ("{rg2: !Rg2Modbus {host: a, poll_rate: .nan}}", ["drivers.rg2.poll_rate: nan"]),
    ],
)
def test_a_malformed_drivers_section_is_one_line_naming_the_key(drivers, words):
    with pytest.raises(ScenarioError) as err:
        load_scenario("row1-optimal", f"{{drivers: {drivers}}}")
    message = str(err.value)
    assert "\n" not in message and message.startswith("--scenario-text: drivers.")
    for word in words:
        assert word in message, (word, message)


def test_a_tag_without_its_mapping_says_to_write_one():
    with pytest.raises(ScenarioError, match=r"write !Simulated \{\}"):
        load_scenario(None, "drivers:\n  rg2: !Simulated\n")


def test_the_station_refuses_a_scenario_with_real_devices(capsys):
    url = _udpm_url()
    code, out, err = refused(
        capsys, "station", "--scenario", "row1-optimal", "--scenario-text", REAL, "--lcm", url
    )
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith("hrc-drake station: error: scenario row1-optimal puts drivers.ur3 ")
    assert "cannot serve half a cell" in err and "`hrc-drake drivers --scenario row1-optimal" in err


def test_drivers_with_nothing_to_drive_exits_2(capsys):
    code, out, err = refused(capsys, "drivers", "--scenario", "row1-optimal", "--lcm", _udpm_url())
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "nothing to drive: drivers.ur3 and drivers.rg2 are !Simulated" in err


def test_drivers_with_no_rg2_at_its_address_exits_1_naming_it(capsys):
    port = free_port()
    text = _rg2_text(port, timeout=0.2)
    code, out, err = refused(capsys, "drivers", "--scenario-text", text, "--lcm", _udpm_url())
    assert code == 1 and out == "" and err.count("\n") == 1, err
    head = "hrc-drake drivers: error: drivers.rg2: no Modbus TCP server answered at"
    assert err.startswith(f"{head} 127.0.0.1:{port} "), err
    assert "Compute Box is on" in err


def test_the_ur3_bridge_stops_on_its_event_leaving_the_arm_stopped():
    """`Ur3Bridge.run(stop=...)`, as `hrc-drake drivers` runs it in a thread: setting the event
    ends it and the arm is stopped (fakes of ur_rtde's interfaces, tests/test_ur3_rtde.py)."""
    from hrc_drake.drivers.ur3_rtde import Ur3Bridge, Ur3RtdeDriver

    control = FakeControl()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), FakeReceive(), control)
    lcm, stop = DrakeLcm("memq://"), threading.Event()
    # A clock standing still: the one command never goes stale, the arm servoes until the stop.
    bridge = Ur3Bridge(driver, lcm, clock=lambda: 0.0)
    lcm.Publish("UR3_COMMAND", lm.ur3_command(1, HOME, [0.0] * 6).encode())
    thread = threading.Thread(target=bridge.run, kwargs={"stop": stop})
    thread.start()
    while not control.named("servoJ") and thread.is_alive():
        time.sleep(0.001)
    stop.set()
    thread.join(timeout=5)
    assert not thread.is_alive() and control.named("servoJ")
    assert control.calls[-1][0] == "servoStop"


def test_drivers_serve_the_rg2_status_until_sigterm():
    """`hrc-drake drivers` with the RG2 on the loopback Modbus server: RG2_STATUS comes on the
    LCM URL; SIGTERM ends it, exit status 0, with its JSON report."""
    url = _udpm_url()
    with Rg2ModbusServer(SimulatedRg2()) as server:
        text = _rg2_text(server.port, poll_rate=50, timeout=0.5)
        argv = ["drivers", "--scenario-text", text, "--lcm", url, "--json"]
        lcm, statuses = DrakeLcm(url), []
        lcm.Subscribe("RG2_STATUS", lambda data: statuses.append(lm.lcmt_rg2_status.decode(data)))
        process = subprocess.Popen(
            [sys.executable, "-m", "hrc_drake.cli", *argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            for _ in range(3000):  # up to a minute on a loaded machine
                if statuses or process.poll() is not None:
                    break
                lcm.HandleSubscriptions(0)  # not waiting in pydrake: it would hold the GIL
                time.sleep(0.02)
            process.send_signal(signal.SIGTERM)
            out, err = process.communicate(timeout=30)
        finally:
            process.kill()
    assert statuses, err
    assert abs(statuses[0].opening - SimulatedRg2().initial[0]) < 0.002
    assert process.returncode == 0, err
    where = f"RG2 over Modbus TCP at 127.0.0.1:{server.port} (unit 65)"
    assert f"{where} serves RG2_COMMAND and RG2_STATUS on {url} at 50 Hz" in err
    (device,) = json.loads(out)["devices"]
    assert device["key"] == "drivers.rg2" and device["published"] >= 1
