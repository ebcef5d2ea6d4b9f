"""The station's safety function (`hrc_drake.cell.station.safety_function`): the stops a robot's own
safety system executes, whatever its controller commands. The diagram tests drive the station
with a `Commander` that ignores the robot's safety mode, and judge the separation by the run's
own check (`hrc_drake.cell.run.safety_check`)."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from hrc_drake.cell.ports import SafetyMode
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.run.safety_check import SafetySample, check_separation
from hrc_drake.cell.scenario import LEAN, load_cell_scenario, motion_options
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.safety_function import (
    PAYLOAD_TOLERANCE,
    RESTART_DELAY,
    UNLOCK_WAIT,
    Brake,
    SafetyFunctionState,
    SeparationVerdict,
    StopCause,
    payload,
    step,
)
from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.activity import min_jerk
from hrc_drake.hri.messages import Prompt, PromptKind
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.scene import TCP, load_cell_frames
from hrc_drake.resources import models_dir
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.scenario.safety import SafetyConfig, SafetyFunctionConfig
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.tasks.spec import load_spec

PERIOD = 0.02
CONFIG = SafetyConfig()
MOVING = SeparationVerdict(moving=True)
STILL = SeparationVerdict()
SHORT = SeparationVerdict(margin=-0.01, clear=False, reduced=True, moving=True)


def _brake(now: float = 0.0) -> Brake:
    return Brake(now, np.zeros(6), np.array([1.0, 0.5, 0, 0, 0, 0]), 5.0)


def _run(state, verdicts, *, external=False, unlock=False, config=CONFIG, start=0.0, stale=False):
    """`state` after one period per verdict, from `start`; the states seen."""
    seen = []
    for k, verdict in enumerate(verdicts):
        now = start + k * PERIOD
        brake = _brake(now)
        state = step(state, verdict, external, unlock, brake, now, config, PERIOD, stale=stale)
        seen.append(state)
    return state, seen


def test_a_brake_stops_every_joint_together_at_the_acceleration_limit():
    brake = _brake()
    q, v = brake.at(0.1)
    assert v == pytest.approx([0.5, 0.25, 0, 0, 0, 0])  # half way: 1 rad/s at 5 rad/s^2
    q, v = brake.at(1.0)
    assert v == pytest.approx(np.zeros(6)) and q == pytest.approx([0.1, 0.05, 0, 0, 0, 0])


def test_the_separation_falling_short_while_moving_is_a_safeguard_stop_that_clears_itself():
    state, _ = _run(SafetyFunctionState(), [SHORT])
    assert state.mode == SafetyMode.SAFEGUARD_STOP and state.cause == StopCause.SEPARATION
    # Held while the arm still moves inside S_p; once it stands still, it resumes by itself
    # after the restart delay.
    state, _ = _run(state, [SHORT] * 10, start=PERIOD)
    assert state.mode == SafetyMode.SAFEGUARD_STOP
    steps = round(RESTART_DELAY / PERIOD) + 1
    state, seen = _run(state, [STILL] * steps, start=11 * PERIOD)
    assert seen[-2].mode == SafetyMode.SAFEGUARD_STOP and state.mode == SafetyMode.NORMAL
    assert state.blend is not None and state.log.safeguard_stops == 1


def test_a_safeguard_stop_with_a_manual_reset_waits_for_the_reset_once_clear():
    """`safeguard_reset: manual`: clear, the stop holds past the restart delay until the reset
    (the unlock input), and without one until the simulated operator's reset."""
    manual = SafetyConfig(function=SafetyFunctionConfig(safeguard_reset="manual", unlock_delay=2.0))
    stopped, _ = _run(SafetyFunctionState(), [SHORT], config=manual)
    state, _ = _run(stopped, [STILL] * 50, config=manual, start=PERIOD)  # 1 s: clear, held
    assert state.mode == SafetyMode.SAFEGUARD_STOP
    reset, _ = _run(state, [STILL], unlock=True, config=manual, start=51 * PERIOD)
    assert reset.mode == SafetyMode.NORMAL and reset.log.events[-1].endswith("reset: resumes")
    # Nobody at the reset: the simulated operator resets 2 s after the stop cleared.
    state, seen = _run(state, [STILL] * 100, config=manual, start=51 * PERIOD)
    resumed = next(k for k, s in enumerate(seen) if s.mode == SafetyMode.NORMAL)
    assert (51 + resumed) * PERIOD == pytest.approx(PERIOD + 2.0, abs=2 * PERIOD)
    with pytest.raises(ScenarioError, match=r"safety\.function\.safeguard_reset.*auto or manual"):
        load_cell_scenario("row1-optimal", "{safety: {function: {safeguard_reset: later}}}")


def test_commands_that_stop_coming_are_a_safeguard_stop_held_until_they_come_again():
    """The real-time link's watchdog: the arm brakes at once and holds while the commands are
    stale, however still it stands; RESTART_DELAY after fresh ones it resumes by itself."""
    state, _ = _run(SafetyFunctionState(), [MOVING], stale=True)
    assert state.mode == SafetyMode.SAFEGUARD_STOP and state.cause == StopCause.STALE_COMMAND
    assert state.brake is not None
    state, _ = _run(state, [STILL] * 100, stale=True, start=PERIOD)
    assert state.mode == SafetyMode.SAFEGUARD_STOP
    steps = round(RESTART_DELAY / PERIOD) + 1
    state, seen = _run(state, [STILL] * steps, start=101 * PERIOD)
    assert seen[-2].mode == SafetyMode.SAFEGUARD_STOP and state.mode == SafetyMode.NORMAL
    assert state.log.safeguard_stops == 1 and state.log.protective_stops == 0
    assert state.log.events[0].endswith("safeguard stop: no fresh command")
    # A protective stop is not unlocked while the commands are stale.
    stopped, _ = _run(SafetyFunctionState(), [MOVING], external=True)
    held, _ = _run(stopped, [STILL] * 400, stale=True, start=PERIOD)
    assert held.mode == SafetyMode.PROTECTIVE_STOP and held.log.unlocks == 0


def test_an_external_stop_is_a_protective_stop_that_waits_for_the_unlock():
    never = SafetyConfig(function=SafetyFunctionConfig(unlock_delay=-1.0))
    state, _ = _run(SafetyFunctionState(), [MOVING] * 5, external=True, config=never)
    assert state.mode == SafetyMode.PROTECTIVE_STOP and state.cause == StopCause.EXTERNAL
    # The input clears; nobody unlocks: it holds, however long.
    state, _ = _run(state, [STILL] * 500, config=never, start=0.1)
    assert state.mode == SafetyMode.PROTECTIVE_STOP
    # An unlock within UNLOCK_WAIT of the stop is refused; after it, it is taken.
    early, _ = _run(SafetyFunctionState(), [MOVING], external=True, config=never)
    early, _ = _run(early, [STILL] * 10, unlock=True, config=never, start=PERIOD)
    assert early.mode == SafetyMode.PROTECTIVE_STOP
    state, _ = _run(state, [STILL], unlock=True, config=never, start=UNLOCK_WAIT + 5.0)
    assert state.mode == SafetyMode.NORMAL and state.log.unlocks == 1


def test_the_simulated_operator_unlocks_after_its_delay_and_not_before_the_wait():
    state, _ = _run(SafetyFunctionState(), [MOVING], external=True)
    state, seen = _run(state, [STILL] * 400, start=PERIOD)
    resumed = next(k for k, s in enumerate(seen) if s.mode == SafetyMode.NORMAL)
    assert (resumed + 1) * PERIOD == pytest.approx(UNLOCK_WAIT, abs=PERIOD)


def test_touching_the_body_while_moving_is_a_protective_stop():
    touch = SeparationVerdict(margin=-0.2, clear=False, contact=True, moving=True)
    state, _ = _run(SafetyFunctionState(), [touch])
    assert state.mode == SafetyMode.PROTECTIVE_STOP and state.cause == StopCause.CONTACT
    # Not while still: a hand bolting the part the arm holds touches it.
    held, _ = _run(SafetyFunctionState(), [SeparationVerdict(contact=True, clear=False)])
    assert held.mode == SafetyMode.NORMAL


def test_bad_safety_function_values_are_refused():
    with pytest.raises(ScenarioError, match=r"safety\.human_speed.*tracked or constant"):
        load_cell_scenario("row1-optimal", "{safety: {human_speed: fast}}")
    with pytest.raises(ScenarioError, match=r"safety\.function\.resume_clearance"):
        load_cell_scenario("row1-optimal", "{safety: {function: {resume_clearance: -1}}}")
    with pytest.raises(ScenarioError, match=r"safety\.hand_acceleration"):
        load_cell_scenario("row1-optimal", "{safety: {hand_acceleration: 0}}")


@pytest.mark.parametrize("assembly", sorted((models_dir() / "assemblies").glob("*.yaml")))
def test_the_payload_is_read_from_the_grippers_opening_alone(assembly):
    """Each part's grasp width, as the fingers close 0.6 mm inside it, is a payload of that
    part (and of any part alike in width); open for a pick (the part's width and the fingers'
    gap each side) or closed on nothing, the gripper carries none."""
    spec = load_spec(assembly)
    widths = load_cell_frames(CellDesign.of(spec)).widths
    gap = MotionOptions().finger_gap
    for part, width in widths.items():
        alike = {p for p, w in widths.items() if abs(w - width) <= PAYLOAD_TOLERANCE - 0.0006}
        assert part in payload(width - 0.0006, widths)
        assert set(payload(width - 0.0006, widths)) >= alike
        assert payload(width + 2.0 * gap, widths) == ()
    assert payload(0.0, widths) == ()


# --- the station, driven by a controller that ignores its robot's safety mode --------------


class Commander(LeafSystem):
    """Commands the arm from `q0` to `q1`, its fastest joint at `speed` rad/s, then holds it
    there, whatever the robot does; `unlock` is 1 from `unlock_at` s on."""

    def __init__(self, q0, q1, speed: float, unlock_at: float = np.inf):
        super().__init__()
        self.q0, self.q1 = np.asarray(q0, float), np.asarray(q1, float)
        self.length = float(np.abs(self.q1 - self.q0).max()) / speed
        self.rate = (self.q1 - self.q0) / self.length
        self.unlock_at = unlock_at
        self.DeclareVectorOutputPort("position", 6, self._position)
        self.DeclareVectorOutputPort("velocity", 6, self._velocity)
        self.DeclareVectorOutputPort("unlock", 1, self._unlock)

    def _position(self, context, output):
        output.SetFromVector(self.q0 + self.rate * min(context.get_time(), self.length))

    def _velocity(self, context, output):
        moving = context.get_time() < self.length
        output.SetFromVector(self.rate if moving else np.zeros(6))

    def _unlock(self, context, output):
        output.SetFromVector([float(context.get_time() >= self.unlock_at)])


class Cell:
    """The station of `row1-optimal` (lean) with `texts` layered on, commanded by a
    `Commander`; `samples` are the run's check's, one a period."""

    def __init__(self, texts, offset, speed, body_script=None, unlock_at=np.inf):
        self.scenario = load_cell_scenario("row1-optimal", [LEAN, *texts])
        self.station = make_cell_station(self.scenario, body_script=body_script)
        self.q0 = np.array(self.scenario.station.ur3.ready, float)
        builder = DiagramBuilder()
        self.side = builder.AddNamedSystem("station", self.station.diagram)
        self.commander = builder.AddNamedSystem(
            "commander", Commander(self.q0, self.q0 + np.asarray(offset), speed, unlock_at)
        )
        for out, port in (
            ("position", "ur3.position"),
            ("velocity", "ur3.velocity"),
            ("unlock", "safety.unlock"),
        ):
            builder.Connect(self.commander.GetOutputPort(out), self.side.GetInputPort(port))
        for value, port in ((0.06, "rg2.opening"), (20.0, "rg2.force")):
            source = builder.AddSystem(ConstantVectorSource([value]))
            builder.Connect(source.get_output_port(), self.side.GetInputPort(port))
        prompt = Prompt(step=1, kind=PromptKind.CHOOSE, proposal="F1")
        source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(prompt)))
        builder.Connect(source.get_output_port(), self.side.GetInputPort("hri.prompt"))
        self.simulator = Simulator(builder.Build())
        self.simulator.Initialize()
        self.samples: list[SafetySample] = []
        self.modes: list[SafetyMode] = []

    def advance_to(self, until: float) -> None:
        """Simulate to `until`, sampling every period."""
        root = self.simulator.get_mutable_context()
        while root.get_time() < until - 1e-9:
            self.simulator.AdvanceTo(round(root.get_time() + PERIOD, 6))
            station = self.side.GetMyContextFromRoot(root)
            x = self.side.GetOutputPort("ur3.state_estimated").Eval(station)
            command = self.commander.GetMyContextFromRoot(root)
            self.samples.append(
                SafetySample(
                    time=root.get_time(),
                    q=x[:6].copy(),
                    v=x[6:].copy(),
                    commanded=self.commander.GetOutputPort("velocity").Eval(command).copy(),
                    opening=float(self.side.GetOutputPort("rg2.state_measured").Eval(station)[0]),
                    carrying=None,
                    body=self.side.GetOutputPort("operator.body").Eval(station),
                )
            )
            self.modes.append(
                SafetyMode(int(self.side.GetOutputPort("safety.mode").Eval(station)[0]))
            )

    def check(self):
        """The run's own check over the samples."""
        acceleration = motion_options(self.scenario).joint_acceleration_limit
        envelope = RobotEnvelope(self.station.design)
        return check_separation(self.samples, envelope, self.scenario.safety, acceleration)

    def log(self):
        return self.station.safety_function_state(self.simulator.get_context()).log


def _tcp(station, q) -> np.ndarray:
    plant = station.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, station.instances[UR3], q)
    tcp = plant.GetFrameByName(TCP, station.instances[GRIPPER])
    return plant.CalcRelativeTransform(context, plant.world_frame(), tcp).translation()


def test_a_protective_stop_holds_the_arm_however_it_is_commanded_until_the_unlock():
    stop = "{body: {enabled: false}, faults: [!ProtectiveStop {task: 1, after: 0.3, duration: 0.5}]"
    texts = [stop + ", safety: {function: {unlock_delay: -1}}}"]
    cell = Cell(texts, [0.6, 0, 0, 0, 0, 0], speed=0.5, unlock_at=6.0)
    cell.advance_to(5.9)
    # Stopped within its braking distance of where the stop came (0.5 rad/s: 0.025 rad), and
    # held there though the command went on to the end and the input cleared at 0.8 s.
    at_stop = next(s for s in cell.samples if s.time >= 0.3 - 1e-9).q[0] - cell.q0[0]
    held = [s for s in cell.samples if s.time >= 0.6]
    assert all(abs(s.q[0] - cell.q0[0] - at_stop) < 0.03 for s in held)
    assert max(abs(s.v).max() for s in held) < 1e-3
    assert cell.modes[-1] == SafetyMode.PROTECTIVE_STOP
    # The unlock at 6 s: the arm goes on to the commanded end.
    cell.advance_to(8.5)
    assert cell.modes[-1] == SafetyMode.NORMAL and cell.log().unlocks == 1
    assert cell.samples[-1].q[0] - cell.q0[0] == pytest.approx(0.6, abs=0.005)


@pytest.mark.parametrize("enabled", [True, False])
def test_a_hand_that_accelerates_toward_the_moving_arm_stops_it_before_s_p(enabled):
    """The arm reaches toward the operator at 1.5 rad/s; the hand sets off toward it from rest
    (minimum jerk, 0.4 s: up to 15 m/s² and 1.9 m/s), stays 1.5 s and goes back. The station's
    function stops the arm: by the run's own check it never moves inside S_p faster than the
    contact speed (it comes inside S_p, by under 2 cm, only at that speed, resuming), and it
    resumes by itself and reaches the commanded end. Without the function the same commands
    break S_p faster."""
    offset = np.array([0, 0.5, -0.8, 0, 0, 0])
    scenario = load_cell_scenario("row1-optimal", [LEAN])
    q0 = np.array(scenario.station.ur3.ready, float)
    rest = np.array(scenario.body.rest_hand, float)
    probe = make_cell_station(scenario)
    target = _tcp(probe, q0 + offset) + np.array([0.15, 0.0, 0.0])

    def hand(now, activity, part):
        t = now - 0.3
        out = min_jerk(t / 0.4) - min_jerk((t - 1.9) / 0.4)
        return rest + out * (target - rest)

    texts = [] if enabled else ["{safety: {function: {enabled: false}}}"]
    cell = Cell(texts, offset, speed=1.5, body_script=hand)
    cell.advance_to(4.0)
    check = cell.check()
    assert check.body_contacts == 0
    if not enabled:
        # Inside S_p faster than the function's contact speed (0.25 m/s), and deeper.
        assert check.worst.speed > 0.25 and check.least_margin < -0.02, check
        assert cell.log().safeguard_stops == 0
        return
    # Inside S_p only ever at the contact speed, which power and force limiting permits.
    assert check.passed and check.least_margin > -0.02, check
    assert check.worst is None or check.worst.speed <= 0.25, check
    assert cell.log().safeguard_stops >= 1 and SafetyMode.SAFEGUARD_STOP in cell.modes
    assert cell.modes[-1] != SafetyMode.SAFEGUARD_STOP
    assert cell.samples[-1].q == pytest.approx(q0 + offset, abs=0.005)
