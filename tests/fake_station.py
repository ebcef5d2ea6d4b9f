"""A small station and controller with the cell's ports, to prove the LCM lockstep on its own
(tests/test_station_lcm.py; also run as a station process: `python tests/fake_station.py URL`,
or in real time, tests/test_station_realtime.py: `python tests/fake_station.py URL --realtime`).

`FakeStation` has the station's ports and the features that make the lockstep's ordering
matter: a discrete servo that integrates the commanded joint positions and velocities, grip
detection with direct feedthrough of the commanded opening, a body that moves with time, and an
operator that answers prompts in a periodic unrestricted update. `FakeController` updates every
`CONTROL_PERIOD` like the Supervisor, commands time-dependent trajectories, and logs everything
it reads.
"""

from __future__ import annotations

import sys

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem

from hrc_drake.cell.link.lockstep import LockstepTimeouts
from hrc_drake.cell.link.realtime import channel_rates
from hrc_drake.cell.link.realtime_server import RealtimeStationServer
from hrc_drake.cell.link.station_server import CellStationServer
from hrc_drake.cell.ports import (
    BodySpheres,
    CellConfiguration,
    PartPlacement,
    PartStatus,
    pose_tuple,
)
from hrc_drake.cell.scenario import plant_step
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.scenario.schema import Scenario

STEP = plant_step(Scenario())  # the plant's time step: the lockstep's exchange period
CONTROL_PERIOD = 0.02  # the default scenario's run.period
# Measured poses carry every bit of a double (a pose read from a plant); the tray part has none,
# as the operator's confirmation would send.
SEATED_POSE = pose_tuple(RigidTransform(RollPitchYaw(0.001, -0.002, 1.5712), [0.3, 0.03, 0.0164]))
HOSTED_POSE = pose_tuple(RigidTransform(RollPitchYaw(0.0, 0.003, -1.57), [0.33, 0.0, 0.0327]))
CONFIGURATION = CellConfiguration(
    (
        (
            "oval_flange_1",
            PartPlacement(PartStatus.SEATED, ("slot_1",), (1,), None, "F1", SEATED_POSE),
        ),
        ("square_flange", PartPlacement(PartStatus.TRAY)),
        (
            "oval_flange_2",
            PartPlacement(PartStatus.SEATED, ("row_1",), (), "square_flange", "F01", HOSTED_POSE),
        ),
    )
)


class FakeStation(LeafSystem):
    """The station's ports around a discrete servo (see the module docstring); `fail_at`:
    raise at that time (a station that breaks)."""

    def __init__(self, fail_at: float | None = None):
        super().__init__()
        self._fail_at = fail_at
        self._position = self.DeclareVectorInputPort("ur3.position", BasicVector(6))
        self._velocity = self.DeclareVectorInputPort("ur3.velocity", BasicVector(6))
        self._opening = self.DeclareVectorInputPort("rg2.opening", BasicVector(1))
        self.DeclareVectorInputPort("rg2.force", BasicVector(1))
        self._prompt = self.DeclareAbstractInputPort("hri.prompt", AbstractValue.Make(Prompt()))
        self._state = self.DeclareDiscreteState(np.r_[np.zeros(12), 0.08, 0.0])
        self._indication = self.DeclareAbstractState(AbstractValue.Make(Indication()))
        self.DeclarePeriodicDiscreteUpdateEvent(STEP, 0.0, self._servo)
        self.DeclarePeriodicUnrestrictedUpdateEvent(CONTROL_PERIOD, 0.0, self._answer)
        state = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort(
            "ur3.state_estimated", 12, self._arm, prerequisites_of_calc=state
        )
        self.DeclareVectorOutputPort(
            "rg2.state_measured", 2, self._gripper, prerequisites_of_calc=state
        )
        self.DeclareVectorOutputPort("rg2.grip_detected", 1, self._grip)
        # A wrist load that changes with the arm's state: every bit of it must cross the link.
        self.DeclareVectorOutputPort("ur3.tcp_force", 6, self._wrench, prerequisites_of_calc=state)
        # A protective stop now and then, to carry both values through the interface.
        self.DeclareVectorOutputPort(
            "safety.stop", 1, lambda c, o: o.SetFromVector([float(c.get_time() % 0.5 > 0.4)])
        )
        # The mode that stop is: a protective stop (3), else normal (1).
        self.DeclareVectorOutputPort(
            "safety.mode",
            1,
            lambda c, o: o.SetFromVector([3.0 if c.get_time() % 0.5 > 0.4 else 1.0]),
        )
        self.DeclareAbstractOutputPort(
            "configuration", lambda: AbstractValue.Make(CellConfiguration()), self._configuration
        )
        self.DeclareAbstractOutputPort(
            "operator.body", lambda: AbstractValue.Make(_body(0.0, 0.0)), self._body
        )
        self.DeclareStateOutputPort("hri.indication", self._indication)

    def _servo(self, context, discrete_state) -> None:
        if self._fail_at is not None and context.get_time() >= self._fail_at:
            raise RuntimeError(f"the fake station broke at t = {context.get_time():.3f} s")
        x = context.get_discrete_state(self._state).get_value()
        q, opening = x[:6], x[12]
        target = self._position.Eval(context)
        q_next = q + STEP * (self._velocity.Eval(context) + 20.0 * (target - q))
        step = np.clip(self._opening.Eval(context)[0] - opening, -0.1 * STEP, 0.1 * STEP)
        v = (q_next - q) / STEP
        discrete_state.set_value(self._state, np.r_[q_next, v, opening + step, step / STEP])

    def _answer(self, context, state) -> None:
        prompt: Prompt = self._prompt.Eval(context)
        indication = context.get_abstract_state(self._indication).get_value()
        now = context.get_time()
        if prompt.kind == PromptKind.CHOOSE and indication.step < prompt.step:
            indication = Indication(prompt.step, prompt.proposal, False, now)
        elif prompt.kind == PromptKind.BOLT and prompt.step == indication.step:
            indication = Indication(indication.step, indication.task, True, now)
        state.get_mutable_abstract_state(self._indication).set_value(indication)

    def _x(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state).get_value()

    def _arm(self, context, output) -> None:
        output.SetFromVector(self._x(context)[:12])

    def _gripper(self, context, output) -> None:
        output.SetFromVector(self._x(context)[12:])

    def _wrench(self, context, output) -> None:
        x = self._x(context)
        output.SetFromVector([0.1 * x[6], -0.2 * x[7], -5.5 + np.sin(x[0]), 0.01, 0.02, x[1] / 3])

    def _grip(self, context, output) -> None:
        # Direct feedthrough of the commanded opening, as the real station's grip sensor has.
        stalled = self._x(context)[12] - self._opening.Eval(context)[0] > 0.001
        output.SetFromVector([1.0 if stalled else 0.0])

    def _configuration(self, context, output) -> None:
        output.set_value(CONFIGURATION)

    def _body(self, context, output) -> None:
        output.set_value(_body(context.get_time(), self._x(context)[0]))


def _body(t: float, q0: float) -> BodySpheres:
    centres = np.array([[0.5 + 0.1 * np.sin(3 * t), q0, 0.3], [0.6, 0.1, 0.4]])
    velocities = np.array([[0.3 * np.cos(3 * t), 0.0, 0.0], [0.0, 0.0, 0.0]])
    return BodySpheres(centres, np.array([0.05, 0.1]), velocities, ((0, 1), (1, 2)))


class FakeController(LeafSystem):
    """Reads every measurement in a periodic unrestricted update and logs it (`log`);
    commands time-dependent trajectories and a prompt that follows the indications."""

    def __init__(self):
        super().__init__()
        self._arm = self.DeclareVectorInputPort("ur3.state_estimated", 12)
        self._gripper = self.DeclareVectorInputPort("rg2.state_measured", 2)
        self._grip = self.DeclareVectorInputPort("rg2.grip_detected", 1)
        self._stop = self.DeclareVectorInputPort("safety.stop", 1)
        self._wrench = self.DeclareVectorInputPort("ur3.tcp_force", 6)
        self._config = self.DeclareAbstractInputPort(
            "configuration", AbstractValue.Make(CellConfiguration())
        )
        self._body = self.DeclareAbstractInputPort(
            "operator.body", AbstractValue.Make(_body(0.0, 0.0))
        )
        self._indication = self.DeclareAbstractInputPort(
            "hri.indication", AbstractValue.Make(Indication())
        )
        self._mode = self.DeclareAbstractState(AbstractValue.Make((Prompt(), 0.0)))
        self.log: list[tuple] = []
        deps = {self.time_ticket(), self.abstract_state_ticket(self._mode)}
        self.DeclareVectorOutputPort("ur3.position", 6, self._position, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("ur3.velocity", 6, self._velocity, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort("rg2.opening", 1, self._opening, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort(
            "rg2.force", 1, lambda c, o: o.SetFromVector([20.0]), prerequisites_of_calc=deps
        )
        self.DeclareAbstractOutputPort(
            "hri.prompt",
            lambda: AbstractValue.Make(Prompt()),
            self._prompt,
            prerequisites_of_calc=deps,
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(CONTROL_PERIOD, 0.0, self._update)

    def _update(self, context, state) -> None:
        now = context.get_time()
        indication: Indication = self._indication.Eval(context)
        body: BodySpheres = self._body.Eval(context)
        self.log.append(
            (
                now,
                tuple(self._arm.Eval(context)),
                tuple(self._gripper.Eval(context)),
                float(self._grip.Eval(context)[0]),
                float(self._stop.Eval(context)[0]),
                self._config.Eval(context),
                tuple(body.centres.ravel()),
                tuple(self._wrench.Eval(context)),
                indication,
            )
        )
        prompt, since = context.get_abstract_state(self._mode).get_value()
        if prompt.kind == PromptKind.NONE or (indication.bolted and indication.step == prompt.step):
            prompt, since = (
                Prompt(prompt.step + 1, PromptKind.CHOOSE, (), f"F{prompt.step + 1}"),
                now,
            )
        elif prompt.kind == PromptKind.CHOOSE and indication.step == prompt.step:
            prompt = Prompt(prompt.step, PromptKind.BOLT, (), prompt.proposal, "part")
            since = now
        state.get_mutable_abstract_state(self._mode).set_value((prompt, since))

    def _since(self, context) -> float:
        return context.get_abstract_state(self._mode).get_value()[1]

    def _position(self, context, output) -> None:
        t = context.get_time() - self._since(context)
        output.SetFromVector(0.2 * np.sin(2 * t + np.arange(6)))

    def _velocity(self, context, output) -> None:
        t = context.get_time() - self._since(context)
        output.SetFromVector(0.4 * np.cos(2 * t + np.arange(6)))

    def _opening(self, context, output) -> None:
        # A ramp from 0.08 m closing at 0.1 m/s: the fake gripper (0.1 m/s) stalls behind it.
        t = context.get_time() - self._since(context)
        output.SetFromVector([max(0.08 - 0.15 * t, 0.02)])

    def _prompt(self, context, output) -> None:
        output.set_value(context.get_abstract_state(self._mode).get_value()[0])


def make_fake_station(fail_at: float | None = None) -> Diagram:
    """`FakeStation` as a diagram exporting its ports."""
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("fake", FakeStation(fail_at))
    for i in range(station.num_input_ports()):
        builder.ExportInput(station.get_input_port(i), station.get_input_port(i).get_name())
    for i in range(station.num_output_ports()):
        builder.ExportOutput(station.get_output_port(i), station.get_output_port(i).get_name())
    diagram = builder.Build()
    diagram.set_name("fake_station")
    return diagram


def main(argv: list[str]) -> int:
    """`fake_station.py URL [START_TIMEOUT [STEP_TIMEOUT]] [--realtime]`: serve a fake station
    (in the lockstep, or in real time at pace 1); print its report's exchange count and the
    station's final joint positions (in real time: the report)."""
    realtime = "--realtime" in argv
    argv = [a for a in argv if a != "--realtime"]
    url = argv[0]
    start = float(argv[1]) if len(argv) > 1 else 30.0
    step = float(argv[2]) if len(argv) > 2 else 30.0
    station = make_fake_station()
    timeouts = LockstepTimeouts(start, step, 0.2)
    if realtime:
        server = RealtimeStationServer(
            station, DrakeLcm(url), channel_rates(Scenario()), STEP, 1.0, timeouts=timeouts
        )
    else:
        server = CellStationServer(station, DrakeLcm(url), STEP, timeouts=timeouts)
    print("serving", flush=True)
    try:
        report = server.serve()
    except Exception as err:
        print(f"error: {err}", file=sys.stderr, flush=True)
        return 1
    if realtime:
        print("report", report, flush=True)
        return 0
    context = station.GetMyContextFromRoot(server.root_context)
    state = station.GetOutputPort("ur3.state_estimated").Eval(context)
    print("report", report["exchanges"], " ".join(repr(float(x)) for x in state), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
