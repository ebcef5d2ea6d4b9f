"""The UR's own safety limits in the station (`hrc_drake.cell.robot_limits`): in reduced
mode its path control caps a command faster than the reduced set, whatever the controller
commands; a limit broken for its detection time is a protective stop. The diagram tests drive
the station with the `Commander` of `test_safety_function`, which ignores the safety mode, and
measure the tool's speed from the arm's measured positions (finite differences of the flange
and the TCP), not from the function's own figures."""

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from test_safety_function import PERIOD, Cell, _tcp

from hrc_drake.cell.ports import SafetyMode
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.robot_limits import FLANGE, LimitPoints, LimitReading, PlanLimits, exceeded
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.safety_function import (
    UNLOCK_WAIT,
    Brake,
    SafetyFunctionState,
    SeparationVerdict,
    StopCause,
    step,
)
from hrc_drake.cell.station.safety_motion import Cap, chase
from hrc_drake.motion.scene import TCP
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS
from hrc_drake.scenario.safety import LimitSetConfig, SafetyConfig
from hrc_drake.scenario.schema import ScenarioError

REDUCED = SafetyConfig().limits.reduced.tool_speed  # 0.25 m/s
DETECTION = SafetyConfig().limits.detection_time
BASE_TURN = [0.9, 0.0, 0.0, 0.0, 0.0, 0.0]  # rad: the base turns the tool across the desk


def _tool_speeds(cell: Cell) -> tuple[np.ndarray, np.ndarray]:
    """(times, the faster of the flange's and the TCP's speed) between the cell's samples."""
    plant = cell.station.plant
    context = plant.CreateDefaultContext()
    arm, gripper = cell.station.instances[UR3], cell.station.instances[GRIPPER]
    frames = (plant.GetFrameByName(FLANGE, arm), plant.GetFrameByName(TCP, gripper))
    points = []
    for sample in cell.samples:
        plant.SetPositions(context, arm, sample.q)
        points.append(
            [
                plant.CalcRelativeTransform(context, plant.world_frame(), f).translation()
                for f in frames
            ]
        )
    points = np.array(points)
    times = np.array([s.time for s in cell.samples])
    speeds = np.linalg.norm(np.diff(points, axis=0), axis=2).max(axis=1) / np.diff(times)
    return times[1:], speeds


def _reduced_from(cell: Cell, when: float) -> None:
    """The station's reduced-mode input on from `when` s (the cell simulated up to then)."""
    cell.advance_to(when)
    root = cell.simulator.get_mutable_context()
    station = cell.side.GetMyMutableContextFromRoot(root)
    cell.side.GetInputPort("sim.safety.reduced").FixValue(station, [1.0])


def _longest_run(flags: np.ndarray) -> int:
    """The most consecutive True in `flags`."""
    best = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        best = max(best, run)
    return best


@pytest.mark.parametrize("enabled", [True, False])
def test_in_reduced_mode_a_faster_command_is_capped_at_the_reduced_tool_speed(enabled):
    """The arm turns its base at 1.5 rad/s (the tool at 0.43 m/s); reduced mode comes at 0.3 s.
    The station caps the tool at the reduced set's 0.25 m/s: over it for no longer than the
    UR's detection time, and within a centimetre a second of it once the arm has slowed; the
    arm still reaches the commanded end, slower, with no stop. Without the limits the same
    command goes through at its own speed."""
    texts = ["{body: {enabled: false}}"]
    if not enabled:
        texts.append("{safety: {limits: {enabled: false}}}")
    cell = Cell(texts, BASE_TURN, speed=1.5)
    _reduced_from(cell, 0.3)
    cell.advance_to(2.5)
    times, speeds = _tool_speeds(cell)
    before = speeds[times <= 0.3]
    assert before.max() > 0.4  # the normal set (1.5 m/s) lets the command through
    after = times > 0.3
    if not enabled:
        assert speeds[after & (times < 0.6)].min() > 0.4
        return
    over = speeds[after] > REDUCED + 1e-3
    assert _longest_run(over) * PERIOD <= DETECTION, speeds[after][:20]
    settled = after & (times > 0.3 + DETECTION)
    assert speeds[settled].max() <= REDUCED + 0.01
    assert all(mode == SafetyMode.REDUCED for mode in cell.modes[16:])
    log = cell.log()
    assert log.protective_stops == 0 and log.safeguard_stops == 0
    assert log.to_json()["capped_time"] > 0.5
    # Capped, not stopped: it went on to the commanded end (0.9 rad at the tool's 0.25 m/s).
    assert cell.samples[-1].q[0] - cell.q0[0] == pytest.approx(0.9, abs=0.005)


def test_a_limit_broken_for_the_detection_time_is_a_protective_stop():
    """With no detection time and a 1 cm/s tolerance, the arm's lag behind the cap when reduced
    mode comes at 0.43 m/s breaks the reduced tool speed: a protective stop (Stop Category 0),
    whose event names the limit; it holds until the unlock, then the arm goes on, capped."""
    limits = "{safety: {limits: {detection_time: 0, tolerance: 0.01, transition: 0}}}"
    cell = Cell(["{body: {enabled: false}}", limits], BASE_TURN, speed=1.5, unlock_at=6.0)
    _reduced_from(cell, 0.3)
    cell.advance_to(5.9)
    log = cell.log()
    assert log.protective_stops == 1 and cell.modes[-1] == SafetyMode.PROTECTIVE_STOP
    assert "protective stop: robot limit: tool speed" in log.events[0], log.events
    assert float(log.events[0].split(":")[0]) < 0.3 + 3 * PERIOD
    cell.advance_to(9.0)
    assert cell.log().unlocks == 1 and cell.modes[-1] == SafetyMode.REDUCED
    assert cell.samples[-1].q[0] - cell.q0[0] == pytest.approx(0.9, abs=0.005)


def test_a_limit_words_stop_the_function_until_the_unlock():
    moving = SeparationVerdict(moving=True)
    brake = Brake(0.0, np.zeros(6), np.array([1.0, 0, 0, 0, 0, 0]), 5.0)
    config = SafetyConfig()
    state = step(
        SafetyFunctionState(), moving, False, False, brake, 0.0, config, PERIOD, limit="tool"
    )
    assert state.mode == SafetyMode.PROTECTIVE_STOP and state.cause == StopCause.LIMIT
    held = step(state, SeparationVerdict(), False, True, brake, 1.0, config, PERIOD)
    assert held.mode == SafetyMode.PROTECTIVE_STOP  # within UNLOCK_WAIT
    freed = step(held, SeparationVerdict(), False, True, brake, UNLOCK_WAIT + 1, config, PERIOD)
    assert freed.mode == SafetyMode.NORMAL and freed.log.unlocks == 1
    # The reduced input alone puts the function in reduced mode.
    reduced = step(
        SafetyFunctionState(), moving, False, False, brake, 0.0, config, PERIOD, reduced=True
    )
    assert reduced.mode == SafetyMode.REDUCED


def test_the_cap_chases_the_command_no_faster_than_the_limits_and_lets_it_go():
    """A command at twice what the limits allow: the target moves at the allowed speed, falls
    behind, and once the command stops it catches up and lets go."""

    def scale(v):
        speed = float(np.abs(v).max())
        return np.inf if speed == 0 else 1.0 / speed  # at most 1 rad/s

    cap, q_cmd = None, np.zeros(6)
    v_cmd = np.array([2.0, 0, 0, 0, 0, 0])
    for k in range(10):
        now = k * PERIOD
        cap = chase(cap, v_cmd * now, v_cmd, now, PERIOD, scale)
        assert isinstance(cap, Cap) and abs(cap.v[0]) <= 1.0 + 1e-9
    q_at, _ = cap.at(10 * PERIOD)
    assert q_at[0] == pytest.approx(10 * PERIOD * 1.0)  # behind the command's 0.4 rad
    q_cmd = v_cmd * 10 * PERIOD
    for k in range(10, 40):
        cap = chase(cap, q_cmd, np.zeros(6), k * PERIOD, PERIOD, scale)
        if cap is None:
            break
    assert cap is None  # caught up and let go


def test_the_limits_read_the_tool_and_the_elbow():
    """At rest nothing moves; turning a wrist joint moves the TCP but not the elbow;
    `exceeded` names the limit broken beyond the tolerance."""
    scenario = load_cell_scenario("row1-optimal", [LEAN])
    design = make_cell_station(scenario).design
    points = LimitPoints(RobotEnvelope(design))
    q = np.array(scenario.station.ur3.ready, float)
    assert points.reading(q, np.zeros(6), None) == LimitReading()
    wrist = points.reading(q, np.array([0, 0, 0, 0, 1.0, 0]), None)
    assert wrist.tool > 0.01 and wrist.elbow == pytest.approx(0.0, abs=1e-9)
    # The shoulder lifts the upper arm: the elbow 0.24 m from its axis (the UR3's upper arm).
    shoulder = points.reading(q, np.array([0, 1.0, 0, 0, 0, 0]), None)
    assert shoulder.elbow == pytest.approx(0.24, abs=0.01) and shoulder.tool > shoulder.elbow
    # The momentum is the arm's and the gripper's mass times their centre of mass's velocity,
    # as Drake computes it from the plant (to the fingers' place: the limits take them at
    # their default opening, this context at its own).
    plant = RobotEnvelope(design).plant
    context = plant.CreateDefaultContext()
    arm, gripper = plant.GetModelInstanceByName(UR3), plant.GetModelInstanceByName(GRIPPER)
    plant.SetPositions(context, arm, q)
    v = np.array([0.4, -0.7, 0.9, 0.3, -0.5, 1.1])
    J = plant.CalcJacobianCenterOfMassTranslationalVelocity(
        context, [arm, gripper], JacobianWrtVariable.kV, plant.world_frame(), plant.world_frame()
    )
    dofs = [plant.GetJointByName(name, arm).velocity_start() for name in UR3_JOINTS]
    mass = plant.CalcTotalMass(context, [arm, gripper])
    expected = mass * np.linalg.norm(J[:, dofs] @ v)
    assert points.reading(q, v, None).momentum == pytest.approx(expected, rel=2e-3)
    limits = LimitSetConfig(tool_speed=0.25, elbow_speed=0.25, momentum=10.0)
    assert "momentum 13.10" in exceeded(LimitReading(momentum=13.1), limits, 0.05)
    assert exceeded(LimitReading(momentum=12.9), limits, 0.05) is None
    assert exceeded(LimitReading(tool=0.29), limits, 0.05) is None
    assert "tool speed 0.31" in exceeded(LimitReading(tool=0.31), limits, 0.05)
    assert points.scale(q, np.zeros(6), None, limits) == np.inf


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{normal: {tool_speed: 0}}", r"safety\.limits\.normal\.tool_speed.*> 0"),
        ("{reduced: {momentum: 30}}", r"safety\.limits\.reduced\.momentum.*above"),
        ("{reduced: {elbow_speed: 2.0}}", r"safety\.limits\.reduced\.elbow_speed.*above"),
        ("{detection_time: -1}", r"safety\.limits\.detection_time.*>= 0"),
        ("{reduced_plane: {normal: [0, 0, 0]}}", r"reduced_plane\.normal.*nonzero"),
        ("{reduced_plane: {point: [0, 1]}}", r"reduced_plane\.point.*\[x, y, z\]"),
    ],
)
def test_bad_limits_are_refused(text, match):
    with pytest.raises(ScenarioError, match=match):
        load_cell_scenario("row1-optimal", f"{{safety: {{limits: {text}}}}}")


def test_the_controller_slows_its_plan_within_the_limits_so_the_cap_seldom_binds(monkeypatch):
    """Row 1 with plans four times faster at the tool (`motion.tcp_speed_limit: 1.0`) beside the
    operator: in reduced mode the controller slows its plan by its own robot model, looking as
    far ahead as its monitor, so the station's cap need not bind (measured: never). With the
    controller's reading of the limits taken away the cap binds for seconds (2.7 s); either
    way the run ends and keeps S_p by its own check."""
    fast = "{motion: {tcp_speed_limit: 1.0}}"
    planned = run_scenario(load_cell_scenario("row1-optimal", [LEAN, fast]))
    monkeypatch.setattr(PlanLimits, "__call__", lambda self, q, qdot, reduced: np.inf)
    unplanned = run_scenario(load_cell_scenario("row1-optimal", [LEAN, fast]))
    for result in (planned, unplanned):
        assert result.done and result.safety_check.passed, result.error
        assert result.safety_function.protective_stops == 0
    assert planned.safety_function.reduced_time > 10.0
    assert planned.safety_function.capped_time < 0.1
    assert unplanned.safety_function.capped_time > 1.0


def test_past_the_trigger_plane_the_reduced_limits_bind():
    """A trigger plane half way along the base's turn: the tool moves at 0.43 m/s in normal
    mode, then, the TCP past the plane, the robot is in reduced mode by itself and the tool
    keeps to 0.25 m/s."""
    probe = Cell(["{body: {enabled: false}}"], BASE_TURN, speed=1.5)
    start = _tcp(probe.station, probe.q0)
    middle = _tcp(probe.station, probe.q0 + 0.5 * np.asarray(BASE_TURN))
    normal = middle - _tcp(probe.station, probe.q0 + 0.4 * np.asarray(BASE_TURN))
    plane = f"{{point: {middle.tolist()}, normal: {normal.tolist()}}}"
    cell = Cell(
        ["{body: {enabled: false}}", f"{{safety: {{limits: {{reduced_plane: {plane}}}}}}}"],
        BASE_TURN,
        speed=1.5,
    )
    assert np.dot(start - middle, normal) < 0  # it starts on the normal side
    cell.advance_to(3.0)
    times, speeds = _tool_speeds(cell)
    crossed = next(k for k, mode in enumerate(cell.modes) if mode == SafetyMode.REDUCED)
    assert all(mode == SafetyMode.NORMAL for mode in cell.modes[:crossed])
    assert all(mode == SafetyMode.REDUCED for mode in cell.modes[crossed:])
    at = cell.samples[crossed].time
    assert speeds[times < at - PERIOD].max() > 0.4
    assert speeds[times > at + DETECTION].max() <= REDUCED + 0.01
    assert cell.samples[-1].q[0] - cell.q0[0] == pytest.approx(0.9, abs=0.005)
