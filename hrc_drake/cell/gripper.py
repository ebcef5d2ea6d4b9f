"""The RG2-like gripper's ports in the station: the opening it takes, what it measures.

A real RG2 takes a target width (and a force) and reports its width and a "grip detected" flag:
the fingers stopped on an object before reaching the target. The simulated one takes the
opening between the finger insides, splits it over its two finger joints (each runs half), and
reports the measured opening, its rate, and grip detection from the same rule.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, Saturation

from hrc_drake.robot_models import RG2_MAX_OPENING

# Fingers held this far outside the commanded opening have stopped on something before their
# target (the RG2 reports its width to 0.1 mm; while the fingers close freely they follow the
# command within a fraction of a millimetre).
STALL_GAP = 0.001  # m


class GripSensor(LeafSystem):
    """`grip_detected` (1): 1 while the measured opening stands more than STALL_GAP wider than
    the commanded one (the fingers stopped on an object before their target, the RG2's rule).
    Inputs: `commanded` (1), `measured` (2: opening, rate)."""

    def __init__(self):
        super().__init__()
        self._commanded = self.DeclareVectorInputPort("commanded", BasicVector(1))
        self._measured = self.DeclareVectorInputPort("measured", BasicVector(2))
        self.DeclareVectorOutputPort("grip_detected", BasicVector(1), self._calc)

    def _calc(self, context, output) -> None:
        opening = self._measured.Eval(context)[0]
        commanded = self._commanded.Eval(context)[0]
        output.SetFromVector([1.0 if opening - commanded > STALL_GAP else 0.0])


def add_gripper_ports(builder: DiagramBuilder, plant: MultibodyPlant, rg2) -> Saturation:
    """Export `rg2.opening` (commanded opening between the finger insides [m], clipped to the
    stroke), `rg2.state_measured` (opening [m], rate [m/s]) and `rg2.grip_detected`; returns the
    system whose output is the commanded opening as the gripper takes it."""
    clip = builder.AddNamedSystem("rg2_clip", Saturation([0.0], [RG2_MAX_OPENING]))
    # Each finger joint runs half the opening; the commanded finger velocities are zero.
    split = builder.AddNamedSystem("rg2_command", MatrixGain(np.array([[0.5], [0.5], [0], [0]])))
    builder.Connect(clip.get_output_port(), split.get_input_port())
    builder.Connect(split.get_output_port(), plant.get_desired_state_input_port(rg2))
    builder.ExportInput(clip.get_input_port(), "rg2.opening")
    measure = builder.AddNamedSystem(
        "rg2_measure", MatrixGain(np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]]))
    )
    builder.Connect(plant.get_state_output_port(rg2), measure.get_input_port())
    builder.ExportOutput(measure.get_output_port(), "rg2.state_measured")
    grip = builder.AddNamedSystem("rg2_grip", GripSensor())
    builder.Connect(clip.get_output_port(), grip.GetInputPort("commanded"))
    builder.Connect(measure.get_output_port(), grip.GetInputPort("measured"))
    builder.ExportOutput(grip.GetOutputPort("grip_detected"), "rg2.grip_detected")
    return clip


__all__ = ["STALL_GAP", "GripSensor", "add_gripper_ports"]
