"""The UR3 driver over ur_rtde at the library boundary: what it calls exists in the installed
ur_rtde with those arities, and against fakes of ur_rtde's interfaces it maps RTDE's outputs to
`UR3_STATUS`, sends `UR3_COMMAND` as `servoJ`, refuses a command too fast, stops on a stale one
and sends nothing in a safety stop. No network: no controller, no URSim."""

from __future__ import annotations

import ast
import inspect
import math
import re
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from drake import lcmt_panda_status
from pydrake.lcm import DrakeLcm

import hrc_drake.drivers.ur3_rtde as ur3_rtde
from hrc_drake.cell.link.lcm_messages import (
    lcmt_ur3_tcp_force,
    tcp_force_value,
    ur3_command,
    ur3_status_values,
)
from hrc_drake.cell.ports import SafetyMode
from hrc_drake.drivers.ur3_rtde import (
    CommandOutcome,
    Ur3Bridge,
    Ur3CommandRefused,
    Ur3DriverError,
    Ur3RtdeDriver,
    Ur3RtdeSettings,
    station_safety_mode,
)
from hrc_drake.robot_names import UR3_VELOCITY_LIMITS

HOME = [0.0, -1.5, 1.2, -1.3, -1.57, 0.3]


class FakeReceive:
    """`rtde_receive.RTDEReceiveInterface` with settable outputs (its methods only: checked
    against the real class by name and arity)."""

    def __init__(self, q=HOME, safety_mode=1, robot_mode=7):
        self.q, self.qd = list(q), [0.0] * 6
        self.target_q, self.target_qd = list(q), [0.0] * 6
        self.target_qdd, self.target_moment = [0.0] * 6, [0.0] * 6
        self.timestamp, self.safety_mode, self.robot_mode = 0.0, safety_mode, robot_mode
        self.tcp_force = [0.0, 0.0, -5.6, 0.0, 0.0, 0.0]
        self.connected = True

    def isConnected(self):
        return self.connected

    def getTimestamp(self):
        return self.timestamp

    def getActualQ(self):
        return list(self.q)

    def getActualQd(self):
        return list(self.qd)

    def getTargetQ(self):
        return list(self.target_q)

    def getTargetQd(self):
        return list(self.target_qd)

    def getTargetQdd(self):
        return list(self.target_qdd)

    def getTargetMoment(self):
        return list(self.target_moment)

    def getActualTCPForce(self):
        return list(self.tcp_force)

    def getSafetyMode(self):
        return self.safety_mode

    def getRobotMode(self):
        return self.robot_mode

    def disconnect(self):
        self.connected = False


class FakeControl:
    """`rtde_control.RTDEControlInterface` recording its calls; `waitPeriod` advances `clock`
    by one period (the tests' wall clock)."""

    def __init__(self, period=0.008):
        self.calls: list[tuple[str, tuple]] = []
        self.clock, self.period = 0.0, period

    def servoJ(self, q, speed, acceleration, time, lookahead_time, gain):
        self.calls.append(("servoJ", (list(q), speed, acceleration, time, lookahead_time, gain)))
        return True

    def servoStop(self, a=10.0):
        self.calls.append(("servoStop", (a,)))
        return True

    def initPeriod(self):
        return timedelta(seconds=self.clock)

    def waitPeriod(self, start):
        self.clock += self.period

    def stopScript(self):
        self.calls.append(("stopScript", ()))

    def disconnect(self):
        self.calls.append(("disconnect", ()))

    def named(self, name):
        return [args for called, args in self.calls if called == name]


def _methods(cls) -> list[str]:
    return [n for n, v in vars(cls).items() if callable(v) and not n.startswith("_")]


def _real_arity(cls, name: str) -> set[tuple[int, int]]:
    """(required, total) positional parameters but self of each of a pybind11 method's
    signatures, from its docstring (pybind11 methods have no inspectable signature)."""
    found = set()
    for params in re.findall(rf"^(?:\d+\. )?{name}\((.*)\) ->", getattr(cls, name).__doc__, re.M):
        parts, depth, current = [], 0, ""
        for ch in params:
            depth += (ch in "[(") - (ch in "])")
            if ch == "," and depth == 0:
                parts.append(current.strip())
                current = ""
            else:
                current += ch
        parts = [p for p in [*parts, current.strip()] if p and not p.startswith("self")]
        found.add((sum("=" not in p for p in parts), len(parts)))
    assert found, f"{cls.__name__}.{name}: no signature in its docstring"
    return found


def _fake_arity(cls, name: str) -> tuple[int, int]:
    params = list(inspect.signature(getattr(cls, name)).parameters.values())[1:]
    return sum(p.default is p.empty for p in params), len(params)


def _real_classes():
    receive = pytest.importorskip("rtde_receive").RTDEReceiveInterface
    control = pytest.importorskip("rtde_control").RTDEControlInterface
    return receive, control


def test_the_fakes_have_ur_rtdes_names_and_arities():
    """Every method of the fakes (and of the driver's protocols) is one of the installed
    ur_rtde's, taking as many positional arguments."""
    receive, control = _real_classes()
    pairs = [
        (FakeReceive, receive),
        (FakeControl, control),
        (ur3_rtde.ReceiveInterface, receive),
        (ur3_rtde.ControlInterface, control),
    ]
    for fake, real in pairs:
        for name in _methods(fake):
            if fake is FakeControl and name == "named":
                continue  # the test's own helper
            assert hasattr(real, name), f"{real.__name__} has no {name}"
            assert _fake_arity(fake, name) in _real_arity(real, name), (fake.__name__, name)


def _driver_calls() -> dict[str, set[str]]:
    """The methods the driver module calls on its receive and control interfaces (attributes
    of `self._receive`/`self._control` and of names bound to them), read from its source."""
    tree = ast.parse(Path(ur3_rtde.__file__).read_text())
    owners = {"_receive": "receive", "_control": "control"}
    aliases = {}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Attribute)
            and node.value.attr in owners
            and isinstance(node.targets[0], ast.Name)
        ):
            aliases[node.targets[0].id] = owners[node.value.attr]
    calls: dict[str, set[str]] = {"receive": set(), "control": set()}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            owner = node.func.value
            if isinstance(owner, ast.Attribute) and owner.attr in owners:
                calls[owners[owner.attr]].add(node.func.attr)
            elif isinstance(owner, ast.Name) and owner.id in aliases:
                calls[aliases[owner.id]].add(node.func.attr)
    return calls


def test_the_driver_calls_only_what_ur_rtde_has():
    """Each method the driver calls is on the installed ur_rtde's class, and declared by the
    driver's protocol and the fakes (so the fake-driven tests below exercise those calls)."""
    receive, control = _real_classes()
    calls = _driver_calls()
    assert {"getActualQ", "getTargetMoment", "getSafetyMode"} <= calls["receive"]
    assert {"servoJ", "servoStop", "initPeriod", "waitPeriod"} <= calls["control"]
    for side, real, protocol, fake in [
        ("receive", receive, ur3_rtde.ReceiveInterface, FakeReceive),
        ("control", control, ur3_rtde.ControlInterface, FakeControl),
    ]:
        missing = sorted(n for n in calls[side] if not hasattr(real, n))
        assert missing == [], f"the driver calls what {real.__name__} lacks: {missing}"
        assert calls[side] <= set(_methods(protocol)) <= set(_methods(fake))


def test_by_default_the_driver_connects_with_ur_rtde(monkeypatch):
    """Without interfaces, the driver makes ur_rtde's two with (host, frequency), which their
    constructors take."""
    receive, control = _real_classes()
    made = []
    for module, cls in [("rtde_receive", receive), ("rtde_control", control)]:
        assert any(req <= 2 <= total for req, total in _real_arity(cls, "__init__"))
        fake = FakeReceive if module == "rtde_receive" else FakeControl
        monkeypatch.setattr(
            f"{module}.{cls.__name__}", lambda *a, m=module, f=fake: made.append((m, a)) or f()
        )
    driver = Ur3RtdeDriver(Ur3RtdeSettings.e_series("192.168.1.7"))
    assert made == [
        ("rtde_receive", ("192.168.1.7", 500.0)),
        ("rtde_control", ("192.168.1.7", 500.0)),
    ]
    assert driver.settings.servo_time == pytest.approx(0.002)


def test_rtde_outputs_map_to_the_status_message():
    """Joint order, units and members as docs/hardware.md says; NaN where the UR3 measures
    nothing; robot_mode the station's safety mode; the message survives encoding."""
    r = FakeReceive(q=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    r.qd = [1.1, 1.2, 1.3, 1.4, 1.5, 1.6]
    r.target_q, r.target_qd = [2.1, 2.2, 2.3, 2.4, 2.5, 2.6], [3.1, 3.2, 3.3, 3.4, 3.5, 3.6]
    r.target_qdd, r.target_moment = [4.1, 4.2, 4.3, 4.4, 4.5, 4.6], [5.1, 5.2, 5.3, 5.4, 5.5, 5.6]
    r.timestamp = 1234.5678
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), r, FakeControl())
    m = lcmt_panda_status.decode(driver.status(987_654_321).encode())
    assert (m.utime, m.robot_utime, m.num_joints) == (987_654_321, 1_234_567_800, 6)
    assert list(m.joint_position) == r.q and list(m.joint_velocity) == r.qd
    assert list(m.joint_position_desired) == r.target_q
    assert list(m.joint_velocity_desired) == r.target_qd
    assert list(m.joint_acceleration_desired) == r.target_qdd
    assert list(m.joint_torque_desired) == r.target_moment
    assert all(math.isnan(x) for x in [*m.joint_torque, *m.joint_torque_external])
    assert len(m.joint_torque) == len(m.joint_torque_external) == 6
    assert m.robot_mode == lcmt_panda_status.kMove
    state, stop, mode = ur3_status_values(m)
    assert list(state) == r.q + r.qd and stop[0] == 0.0 and mode[0] == SafetyMode.NORMAL


@pytest.mark.parametrize(
    "safety, robot, expected",
    [
        (1, 7, SafetyMode.NORMAL),
        (2, 7, SafetyMode.REDUCED),
        (3, 7, SafetyMode.PROTECTIVE_STOP),
        (5, 7, SafetyMode.SAFEGUARD_STOP),
        (7, 7, SafetyMode.PROTECTIVE_STOP),  # robot emergency stop
        (9, 7, SafetyMode.PROTECTIVE_STOP),  # fault
        (12, 7, SafetyMode.SAFEGUARD_STOP),  # automatic mode safeguard stop
        (42, 7, SafetyMode.PROTECTIVE_STOP),  # a code we do not know
        (1, 3, SafetyMode.SAFEGUARD_STOP),  # powered off
        (1, 5, SafetyMode.SAFEGUARD_STOP),  # idle
        (3, 5, SafetyMode.PROTECTIVE_STOP),
    ],
)
def test_safety_and_robot_modes_reach_the_controller_as_the_stations(safety, robot, expected):
    assert station_safety_mode(safety, robot) == expected
    driver = Ur3RtdeDriver(
        Ur3RtdeSettings("ur3"), FakeReceive(safety_mode=safety, robot_mode=robot), FakeControl()
    )
    _, stop, mode = ur3_status_values(driver.status(0))
    assert mode[0] == expected and stop[0] == float(expected.stopped)


def _command(stamp: int, q) -> object:
    return ur3_command(stamp, q, [0.0] * 6)


@pytest.mark.parametrize("settings", [Ur3RtdeSettings.cb3("ur3"), Ur3RtdeSettings.e_series("ur3")])
def test_a_command_is_sent_as_servoj(settings):
    control = FakeControl()
    driver = Ur3RtdeDriver(settings, FakeReceive(), control)
    q = [x + 0.001 for x in HOME]
    assert driver.command(_command(10_000, q)) == CommandOutcome.SENT
    (args,) = control.named("servoJ")
    assert args[0] == pytest.approx(q) and args[3:] == (settings.servo_time, 0.1, 300.0)
    assert driver.servoing and control.named("servoStop") == []


def test_commands_up_to_the_velocity_limits_pass_and_beyond_are_refused():
    """Against the previous command over their stamps' interval: 99 % of a joint's limit is
    sent, 101 % refused with the joint named, the arm stopped (servoStop) and nothing sent."""
    control = FakeControl()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), FakeReceive(), control)
    driver.command(_command(0, HOME))
    dt, limit = 0.010, UR3_VELOCITY_LIMITS[4]
    q = np.array(HOME)
    q[4] += 0.99 * limit * dt
    assert driver.command(_command(10_000, q)) == CommandOutcome.SENT
    q[4] += 1.01 * limit * dt
    with pytest.raises(Ur3CommandRefused, match=r"wrist_2_joint.*servoStop"):
        driver.command(_command(20_000, q))
    assert len(control.named("servoJ")) == 2 and control.named("servoStop") == [(10.0,)]
    assert not driver.servoing


def test_a_first_command_away_from_the_arm_is_refused():
    """Starting to servo, the command is checked against the measured position over one
    period: a jump of 0.1 rad in 8 ms (12.5 rad/s) is refused and nothing is sent."""
    control = FakeControl()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), FakeReceive(), control)
    q = list(HOME)
    q[0] += 0.1
    with pytest.raises(Ur3CommandRefused, match=r"shoulder_pan_joint.*measured position"):
        driver.command(_command(0, q))
    assert control.named("servoJ") == []


def test_a_stale_command_stops_the_arm():
    settings = Ur3RtdeSettings.cb3("ur3")
    control = FakeControl()
    driver = Ur3RtdeDriver(settings, FakeReceive(), control)
    message = _command(0, HOME)
    assert driver.follow(message, age=0.0) == CommandOutcome.SENT
    assert driver.follow(message, age=settings.stale_after - 1e-3) == CommandOutcome.SENT
    assert driver.follow(message, age=settings.stale_after + 1e-3) == CommandOutcome.STALE
    assert control.named("servoStop") == [(10.0,)] and not driver.servoing
    assert len(control.named("servoJ")) == 2


def test_rtde_tcp_force_maps_to_the_wrist_load_message():
    """actual_TCP_force, force then moment, as UR3_TCP_FORCE (`ur3.tcp_force` on the
    controller's side), every bit; a reading of another length is refused."""
    r = FakeReceive()
    r.tcp_force = [0.25, -1.5, 7.125, 0.01, -0.02, 1 / 3]
    driver = Ur3RtdeDriver(Ur3RtdeSettings.e_series("ur3e"), r, FakeControl())
    message = lcmt_ur3_tcp_force.decode(driver.tcp_force(123).encode())
    assert message.utime == 123
    (wrench,) = tcp_force_value(message)
    assert list(wrench) == r.tcp_force
    r.tcp_force = [0.0] * 3
    with pytest.raises(Ur3DriverError, match="actual_TCP_force: 3 values"):
        driver.tcp_force(124)


def _status_counter(lcm: DrakeLcm) -> list:
    statuses = []
    lcm.Subscribe("UR3_STATUS", lambda data: statuses.append(lcmt_panda_status.decode(data)))
    return statuses


def test_the_bridge_publishes_status_each_period_and_stops_on_a_stale_command():
    """Over LCM (in-process memq): one UR3_COMMAND, then none; at 125 Hz the arm servoes for
    the 74 ms bound (cycles at 0..72 ms) and is stopped at 80 ms; a status every cycle."""
    control, receive = FakeControl(period=0.008), FakeReceive()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), receive, control)
    lcm = DrakeLcm("memq://")
    statuses = _status_counter(lcm)
    loads = []
    lcm.Subscribe("UR3_TCP_FORCE", lambda data: loads.append(lcmt_ur3_tcp_force.decode(data)))
    bridge = Ur3Bridge(driver, lcm, clock=lambda: control.clock)
    lcm.Publish("UR3_COMMAND", _command(5, HOME).encode())
    bridge.run(cycles=20)
    lcm.HandleSubscriptions(0)
    assert len(control.named("servoJ")) == 10 and control.named("servoStop") == [(10.0,)]
    assert [s.utime for s in statuses] == [round(8_000 * i) for i in range(20)]
    assert [m.utime for m in loads] == [s.utime for s in statuses]


def test_the_bridge_ends_on_a_refused_command_with_the_arm_stopped():
    control, receive = FakeControl(), FakeReceive()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), receive, control)
    driver.command(_command(0, HOME))
    lcm = DrakeLcm("memq://")
    bridge = Ur3Bridge(driver, lcm, clock=lambda: control.clock)
    lcm.Publish("UR3_COMMAND", _command(10_000, [x + 0.5 for x in HOME]).encode())
    with pytest.raises(Ur3CommandRefused):
        bridge.run(cycles=5)
    assert control.named("servoStop") == [(10.0,)] and not driver.servoing
    assert len(control.named("servoJ")) == 1


@pytest.mark.parametrize("code", [3, 5])
def test_nothing_is_sent_in_a_safety_stop(code):
    """In a protective (3) or safeguard (5) stop no call reaches the controller, not even
    servoStop; once it clears, servoing starts again from the measured position."""
    control, receive = FakeControl(), FakeReceive()
    driver = Ur3RtdeDriver(Ur3RtdeSettings.cb3("ur3"), receive, control)
    driver.command(_command(0, HOME))
    sent = list(control.calls)
    receive.safety_mode = code
    assert driver.command(_command(10_000, HOME)) == CommandOutcome.SAFETY_STOP
    assert driver.follow(_command(20_000, HOME), age=1.0) == CommandOutcome.SAFETY_STOP
    assert control.calls == sent and not driver.servoing
    receive.safety_mode, receive.q = 1, [x + 0.2 for x in HOME]  # it was pushed while stopped
    with pytest.raises(Ur3CommandRefused, match="measured position"):
        driver.command(_command(30_000, HOME))
    assert driver.command(_command(40_000, receive.q)) == CommandOutcome.SENT
