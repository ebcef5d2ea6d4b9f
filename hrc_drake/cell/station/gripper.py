"""The RG2-like gripper's ports in the station: the opening and force it takes, what it measures.

A real RG2 takes a target width and a gripping force, closes until it reaches the width or the
force, and reports its width and a "grip detected" flag: the fingers stopped on an object before
reaching the target. The simulated one does the same. It takes the opening between the finger
insides (each of its two finger joints runs half) and the force, drives the fingers with a
force-limited servo (`FingerServo`), so that a part is held by the pads' contact and friction
alone, and reports the measured opening, its rate, and grip detection from the RG2's rule.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, Saturation

# The RG2's gripping force range (hrc_drake.robot_models): a command outside it is clipped to
# it, as the opening is clipped to the stroke.
from hrc_drake.robot_models import RG2_MAX_FORCE, RG2_MAX_OPENING, RG2_MIN_FORCE

# Fingers held this far outside the commanded opening have stopped on something before their
# target (the RG2 reports its width to 0.1 mm; while the fingers close freely they follow the
# command within a fraction of a millimetre).
STALL_GAP = 0.001  # m


def stopped_short(opening: float, commanded: float) -> bool:
    """Whether fingers at `opening` stand more than STALL_GAP wider than `commanded`: stopped on
    an object (or stuck) before the target, the RG2's "grip detected"."""
    return opening - commanded > STALL_GAP


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
        output.SetFromVector([1.0 if stopped_short(opening, commanded) else 0.0])


class FingerServo(LeafSystem):
    """The RG2's force-limited finger servo, over the plant's own PD actuators of the finger
    joints (gain `kp` [N/m]; SAP integrates them implicitly over the plant's `time_step`).

    Each finger is driven toward half the commanded opening, but its desired position is kept
    within `force / kp` of where the finger will be at the end of the step if it keeps its
    speed: the PD then pushes with at most the commanded force (less its damping while the
    finger moves; a still finger exactly that), and resists only changes of speed beyond it,
    so a weak grip still closes at the command's pace. A finger that reaches its target stops
    there; one that meets a part stalls on it and squeezes it with the commanded force,
    whatever the target past it. Inputs: `opening` (1, m), `force` (1, N), `finger_state` (4:
    the two finger joints' positions, then velocities). Output: `desired_state` (4) for the
    plant."""

    def __init__(self, kp: float, time_step: float):
        super().__init__()
        self._kp, self._h = kp, time_step
        self._opening = self.DeclareVectorInputPort("opening", BasicVector(1))
        self._force = self.DeclareVectorInputPort("force", BasicVector(1))
        self._fingers = self.DeclareVectorInputPort("finger_state", BasicVector(4))
        self.DeclareVectorOutputPort("desired_state", BasicVector(4), self._calc)

    def _calc(self, context, output) -> None:
        state = self._fingers.Eval(context)
        ahead = state[:2] + self._h * state[2:]
        reach = self._force.Eval(context)[0] / self._kp
        target = 0.5 * self._opening.Eval(context)[0]
        desired = ahead + np.clip(target - ahead, -reach, reach)
        output.SetFromVector([desired[0], desired[1], 0.0, 0.0])


def add_gripper_ports(
    builder: DiagramBuilder, plant: MultibodyPlant, rg2, kp: float, faults=None, export=None
) -> None:
    """Export `rg2.opening` (commanded opening between the finger insides [m], clipped to the
    stroke), `rg2.force` (commanded gripping force [N], clipped to the RG2's range),
    `rg2.state_measured` (opening [m], rate [m/s]) and `rg2.grip_detected`; the fingers'
    servo has the plant's finger gain `kp` [N/m]. With `faults` (the station's
    `hrc_drake.cell.station.faults.FaultInjector`) the command reaches the servo through it.
    `export(port, name)` exports `rg2.state_measured` (default: `builder.ExportOutput`; the
    station's puts its sensor model between)."""
    clip = builder.AddNamedSystem("rg2_clip", Saturation([0.0], [RG2_MAX_OPENING]))
    force = builder.AddNamedSystem("rg2_force_clip", Saturation([RG2_MIN_FORCE], [RG2_MAX_FORCE]))
    servo = builder.AddNamedSystem("rg2_servo", FingerServo(kp, plant.time_step()))
    commanded = (clip.get_output_port(), force.get_output_port())
    if faults is not None:
        builder.Connect(clip.get_output_port(), faults.GetInputPort("opening"))
        builder.Connect(force.get_output_port(), faults.GetInputPort("force"))
        commanded = (faults.GetOutputPort("opening"), faults.GetOutputPort("force"))
    builder.Connect(commanded[0], servo.GetInputPort("opening"))
    builder.Connect(commanded[1], servo.GetInputPort("force"))
    builder.Connect(plant.get_state_output_port(rg2), servo.GetInputPort("finger_state"))
    builder.Connect(servo.GetOutputPort("desired_state"), plant.get_desired_state_input_port(rg2))
    builder.ExportInput(clip.get_input_port(), "rg2.opening")
    builder.ExportInput(force.get_input_port(), "rg2.force")
    measure = builder.AddNamedSystem(
        "rg2_measure", MatrixGain(np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]]))
    )
    builder.Connect(plant.get_state_output_port(rg2), measure.get_input_port())
    if faults is not None:
        builder.Connect(measure.get_output_port(), faults.GetInputPort("measured"))
    (export or builder.ExportOutput)(measure.get_output_port(), "rg2.state_measured")
    grip = builder.AddNamedSystem("rg2_grip", GripSensor())
    builder.Connect(clip.get_output_port(), grip.GetInputPort("commanded"))
    builder.Connect(measure.get_output_port(), grip.GetInputPort("measured"))
    builder.ExportOutput(grip.GetOutputPort("grip_detected"), "rg2.grip_detected")


__all__ = [
    "RG2_MAX_FORCE",
    "RG2_MIN_FORCE",
    "STALL_GAP",
    "FingerServo",
    "GripSensor",
    "add_gripper_ports",
    "stopped_short",
]
