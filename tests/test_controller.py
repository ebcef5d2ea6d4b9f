"""The controller uses only what a real cell offers, and checks what it commands against what it
measures: a pushed arm or an empty gripper stops the task with the reason."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from hrc_drake.cell.controller.build import COMMANDED, MEASURED, connect_controller, make_controller
from hrc_drake.cell.controller.supervisor import Mode
from hrc_drake.cell.ports import BodySpheres, CellConfiguration, PartPlacement, PartStatus
from hrc_drake.cell.run.run import build_closed_loop, shared_planner
from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario, motion_options
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.motion.service import InlinePlanService, planner_function
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.solve import exact_policy


class _BareCell(LeafSystem):
    """A stand-in for a real cell that offers exactly the measured ports of docs/station.md and
    takes exactly the commanded ones: the arm is where it was commanded, the gripper stands at
    its command, every part sits in the tray, nobody is near, and the operator confirms every
    proposal."""

    def __init__(self, parts):
        super().__init__()
        tray = CellConfiguration(tuple((p, PartPlacement(PartStatus.TRAY)) for p in sorted(parts)))
        self._position = self.DeclareVectorInputPort("ur3.position", 6)
        self.DeclareVectorInputPort("ur3.velocity", 6)
        self._opening = self.DeclareVectorInputPort("rg2.opening", 1)
        self.DeclareVectorInputPort("rg2.force", 1)
        self._prompt = self.DeclareAbstractInputPort("hri.prompt", AbstractValue.Make(Prompt()))
        self.DeclareVectorOutputPort("ur3.state_estimated", 12, self._arm)
        # The wrist carries nothing: no load (the guarded descent never trips).
        self.DeclareVectorOutputPort("ur3.tcp_force", 6, lambda c, o: o.SetFromVector([0] * 6))
        self.DeclareVectorOutputPort("rg2.state_measured", 2, self._gripper)
        self.DeclareVectorOutputPort("rg2.grip_detected", 1, lambda c, o: o.SetFromVector([0]))
        self.DeclareVectorOutputPort("safety.stop", 1, lambda c, o: o.SetFromVector([0]))
        self.DeclareVectorOutputPort("safety.mode", 1, lambda c, o: o.SetFromVector([1]))
        self.DeclareAbstractOutputPort(
            "configuration", lambda: AbstractValue.Make(tray), lambda c, o: o.set_value(tray)
        )
        nobody = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
        self.DeclareAbstractOutputPort(
            "operator.body", lambda: AbstractValue.Make(nobody), lambda c, o: o.set_value(nobody)
        )
        self.DeclareAbstractOutputPort(
            "hri.indication", lambda: AbstractValue.Make(Indication()), self._indication
        )

    def _arm(self, context, output):
        # A perfect servo: the arm is where it is commanded.
        output.SetFromVector(np.concatenate([self._position.Eval(context), np.zeros(6)]))

    def _gripper(self, context, output):
        output.SetFromVector([self._opening.Eval(context)[0], 0.0])

    def _indication(self, context, output):
        prompt: Prompt = self._prompt.Eval(context)
        if prompt.kind == PromptKind.CHOOSE:
            output.set_value(Indication(prompt.step, prompt.proposal))
        else:
            output.set_value(Indication())


def test_the_controller_runs_against_a_cell_that_offers_only_real_ports():
    scenario = load_cell_scenario("row1-optimal", LEAN)
    space = generate_states(scenario_spec := _spec(scenario))
    design = cell_design(scenario, scenario_spec)
    options = motion_options(scenario)
    planner = shared_planner(options, design)
    plans = InlinePlanService(planner_function(planner))
    controller = make_controller(
        scenario, design, space, exact_policy(space), plans, planner.q_home, options
    )
    diagram = controller.diagram
    inputs = {diagram.get_input_port(i).get_name() for i in range(diagram.num_input_ports())}
    outputs = {diagram.get_output_port(i).get_name() for i in range(diagram.num_output_ports())}
    assert inputs == set(MEASURED)
    assert outputs == {*COMMANDED, "status"}

    builder = DiagramBuilder()
    cell = builder.AddSystem(_BareCell(design.instance_names))
    brain = builder.AddSystem(diagram)
    connect_controller(builder, cell, brain)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.5)
    root = simulator.get_context()
    status = diagram.GetOutputPort("status").Eval(diagram.GetMyContextFromRoot(root))
    # It proposed the policy's first task, took the confirmation, planned, and started moving.
    prompt = status.question.prompt
    assert prompt.kind == PromptKind.CHOOSE and prompt.proposal == "F1"
    assert status.mode == Mode.EXECUTE and status.plan.task == "F1"
    assert status.error is None


def _spec(scenario):
    from hrc_drake.tasks.spec import load_spec

    return load_spec(scenario.assembly_path)


# The operator answers at once: these tests time the arm's motion, not the indication delay.
NO_DELAY = "{interaction: {delay: {distribution: fixed, median: 0}}}"


def _loop(scenario_name: str = "row1-optimal"):
    scenario = load_cell_scenario(scenario_name, [LEAN, NO_DELAY])
    return build_closed_loop(scenario)


@pytest.mark.slow
def test_an_arm_pushed_off_its_path_stops_the_task_with_the_reason():
    # 150 N·m on the shoulder pan from 2 s into the first task, well past the UR3's 56 N·m
    # shoulder servo.
    push = "{faults: [!Pushed {task: 1, after: 2.0, torque: 150}]}"
    loop = build_closed_loop(load_cell_scenario("row1-optimal", [LEAN, NO_DELAY, push]))
    assert loop.advance_to(2.0) == Mode.EXECUTE  # on its way to the first part
    assert loop.advance_to(4.0) == Mode.FAILED
    status = loop.status
    assert "rad from its command" in status.error and "pushed or blocked" in status.error
    # The arm holds where it was stopped, not where its plan or its home would take it.
    q = loop.station.plant.GetPositions(
        loop.station.plant.GetMyContextFromRoot(loop.root_context),
        loop.station.instances["ur3"],
    )
    assert np.allclose(status.command(loop.root_context.get_time()).q, status.q_hold)
    assert np.abs(q - np.asarray(status.q_hold)).max() < 0.2
    assert status.history == ()  # the task was not counted as done


@pytest.mark.slow
def test_an_empty_gripper_where_it_should_hold_a_part_stops_the_task():
    loop = _loop()
    assert loop.advance_to(1.0) == Mode.EXECUTE
    part = loop.status.plan.instance
    # Someone takes the part out of the tray before the robot gets there and puts it down at
    # the far corner of the table.
    plant = loop.station.plant
    plant.SetFreeBodyPose(
        plant.GetMyMutableContextFromRoot(loop.root_context),
        loop.station.part_body(part),
        RigidTransform([0.65, -0.42, 0.006]),
    )
    assert loop.advance_to(8.0) == Mode.HANDOVER
    status = loop.status
    # The fingers close on nothing: the Supervisor looks for the part where the configuration
    # sensor reads it, finds it out of the arm's reach, and hands the task over (the operator
    # then does it by hand: tests/test_faults.py).
    assert any(f"{part} is not in the gripper" in e for e in status.events)
    assert f"cannot pick {part} from where it lies" in status.recovery.handover
    assert "out of reach" in status.recovery.handover
    assert status.question.prompt.kind == "handover" and status.question.prompt.part == part
    assert [d.cause for d in status.detections] == ["grip"]
    assert status.history == ()
