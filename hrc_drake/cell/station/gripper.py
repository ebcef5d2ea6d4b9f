"""The RG2-like gripper's ports in the station: the opening and force it takes, what it measures.

A real RG2 takes a target width and a gripping force, closes until it reaches the width or the
force, and reports its width and a "grip detected" flag: the fingers stopped on an object before
reaching the target. The simulated one does the same. As the real one, it has one motor: the
model's crank (`hrc_drake.rg2_kinematics`), which its linkage turns into both fingers' motion
(Drake coupler constraints). It takes the opening between the pads and the force, drives the
crank with a force-limited servo (`FingerServo`), so that a part is held by the pads' contact
and friction alone, and reports the opening measured from the crank's angle, its rate, and grip
detection from the RG2's rule.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PdControllerGains
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, Saturation

from hrc_drake.cell.station.arm_servo import servo_actuators
from hrc_drake.rg2_kinematics import (
    MAX_ANGLE,
    TCP_OPENING,
    crank_angle,
    opening_at,
    opening_rate,
)

# The RG2's gripping force range (hrc_drake.robot_models): a command outside it is clipped to
# it, as the opening is clipped to the stroke.
from hrc_drake.robot_models import RG2_DRIVE_JOINT, RG2_MAX_FORCE, RG2_MAX_OPENING, RG2_MIN_FORCE

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


def crank_gain(gain: float) -> float:
    """The crank's gain [N·m/rad or N·m·s/rad] that acts as `gain` per finger [N/m or N·s/m]
    at TCP_OPENING: a finger `d` from its target pushes with gain * d; the crank's lever there
    (opening_rate) turns that into gain * rate**2 / 2 per radian (wider, the lever shortens and
    the fingers' stiffness falls with its square; the force limit holds at every opening)."""
    return gain * opening_rate(crank_angle(TCP_OPENING)) ** 2 / 2.0


def set_finger_gains(plant: MultibodyPlant, rg2, kp: float, kd: float) -> None:
    """Give the gripper's one actuator (its crank) the PD gains that act as `kp` [N/m] and `kd`
    [N·s/m] per finger (`crank_gain`), before `plant` is finalized."""
    for actuator in servo_actuators(plant, rg2):
        actuator.set_controller_gains(PdControllerGains(p=crank_gain(kp), d=crank_gain(kd)))


class FingerServo(LeafSystem):
    """The RG2's force-limited finger servo, over the plant's own PD actuator of the crank
    (gain `kp` [N·m/rad], `crank_gain`; SAP integrates it implicitly over the plant's
    `time_step`).

    The crank is driven toward the commanded opening's angle, but its desired angle is kept
    within `force * opening_rate / kp` of where it will be at the end of the step if it keeps
    its speed: the PD then pushes each pad with at most the commanded force (less its damping
    while the fingers move; still fingers exactly that), and resists only changes of speed
    beyond it, so a weak grip still closes at the command's pace. Fingers that reach their
    target stop there; fingers that meet a part stall on it and squeeze it with the commanded
    force, whatever the target past it. Inputs: `opening` (1, m), `force` (1, N),
    `drive_state` (2: the crank's angle and rate). Output: `desired_state` (2) for the plant."""

    def __init__(self, kp: float, time_step: float):
        super().__init__()
        self._kp, self._h = kp, time_step
        # The last commanded opening and its crank angle: the command holds for many steps.
        self._target = (float("nan"), float("nan"))
        self._opening = self.DeclareVectorInputPort("opening", BasicVector(1))
        self._force = self.DeclareVectorInputPort("force", BasicVector(1))
        self._drive = self.DeclareVectorInputPort("drive_state", BasicVector(2))
        self.DeclareVectorOutputPort("desired_state", BasicVector(2), self._calc)

    def _calc(self, context, output) -> None:
        angle, rate = self._drive.Eval(context)
        ahead = angle + self._h * rate
        opening = min(max(float(self._opening.Eval(context)[0]), 0.0), RG2_MAX_OPENING)
        lever = opening_rate(min(max(ahead, 0.0), MAX_ANGLE))
        reach = self._force.Eval(context)[0] * lever / self._kp
        if opening != self._target[0]:
            self._target = (opening, crank_angle(opening))
        # Plain floats: np.clip on one number costs more than the rest of the step's work.
        desired = ahead + min(max(self._target[1] - ahead, -reach), reach)
        output.SetFromVector([desired, 0.0])


class OpeningSensor(LeafSystem):
    """The opening between the pads [m] and its rate [m/s] from the crank's angle and rate, as
    the RG2 reports its width from its motor's. Input `drive_state` (2); output `measured`
    (2)."""

    def __init__(self):
        super().__init__()
        self._drive = self.DeclareVectorInputPort("drive_state", BasicVector(2))
        self.DeclareVectorOutputPort("measured", BasicVector(2), self._calc)

    def _calc(self, context, output) -> None:
        angle, rate = self._drive.Eval(context)
        output.SetFromVector([opening_at(angle), opening_rate(angle) * rate])


def _drive_selector(plant: MultibodyPlant, rg2) -> np.ndarray:
    """The 2 x (nq + nv) matrix that picks the crank's angle and rate from the gripper's state."""
    joint = plant.GetJointByName(RG2_DRIVE_JOINT, rg2)
    q = np.zeros(plant.num_positions())
    v = np.zeros(plant.num_velocities())
    q[joint.position_start()], v[joint.velocity_start()] = 1.0, 1.0
    q, v = plant.GetPositionsFromArray(rg2, q), plant.GetVelocitiesFromArray(rg2, v)
    selector = np.zeros((2, len(q) + len(v)))
    selector[0, : len(q)], selector[1, len(q) :] = q, v
    return selector


def add_gripper_ports(
    builder: DiagramBuilder, plant: MultibodyPlant, rg2, kp: float, faults=None, export=None
) -> None:
    """Export `rg2.opening` (commanded opening between the pads [m], clipped to the stroke),
    `rg2.force` (commanded gripping force [N], clipped to the RG2's range),
    `rg2.state_measured` (opening [m], rate [m/s]) and `rg2.grip_detected`; the servo has the
    plant's finger gain `kp` [N/m per finger, `set_finger_gains`]. With `faults` (the station's
    `hrc_drake.cell.station.faults.FaultInjector`) the command reaches the servo through it.
    `export(port, name)` exports `rg2.state_measured` (default: `builder.ExportOutput`; the
    station's puts its sensor model between)."""
    clip = builder.AddNamedSystem("rg2_clip", Saturation([0.0], [RG2_MAX_OPENING]))
    force = builder.AddNamedSystem("rg2_force_clip", Saturation([RG2_MIN_FORCE], [RG2_MAX_FORCE]))
    servo = builder.AddNamedSystem("rg2_servo", FingerServo(crank_gain(kp), plant.time_step()))
    drive = builder.AddNamedSystem("rg2_drive", MatrixGain(_drive_selector(plant, rg2)))
    builder.Connect(plant.get_state_output_port(rg2), drive.get_input_port())
    commanded = (clip.get_output_port(), force.get_output_port())
    if faults is not None:
        builder.Connect(clip.get_output_port(), faults.GetInputPort("opening"))
        builder.Connect(force.get_output_port(), faults.GetInputPort("force"))
        commanded = (faults.GetOutputPort("opening"), faults.GetOutputPort("force"))
    builder.Connect(commanded[0], servo.GetInputPort("opening"))
    builder.Connect(commanded[1], servo.GetInputPort("force"))
    builder.Connect(drive.get_output_port(), servo.GetInputPort("drive_state"))
    builder.Connect(servo.GetOutputPort("desired_state"), plant.get_desired_state_input_port(rg2))
    builder.ExportInput(clip.get_input_port(), "rg2.opening")
    builder.ExportInput(force.get_input_port(), "rg2.force")
    measure = builder.AddNamedSystem("rg2_measure", OpeningSensor())
    builder.Connect(drive.get_output_port(), measure.get_input_port())
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
    "OpeningSensor",
    "add_gripper_ports",
    "crank_gain",
    "set_finger_gains",
    "stopped_short",
]
