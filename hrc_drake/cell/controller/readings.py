"""What the Supervisor reads of the cell in one update: its measured input ports, each read only
when a part of the Supervisor asks for it (a port is evaluated as lazily as a real controller
polls a device), and passed to the parts as one narrow value."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, InputPort, LeafSystem

from hrc_drake.cell.controller.supervisor_state import N_JOINTS
from hrc_drake.cell.ports import NOBODY, BodySpheres, CellConfiguration, SafetyMode
from hrc_drake.hri.messages import Indication


@dataclass(frozen=True)
class SupervisorInputs:
    """The Supervisor's input ports (see `hrc_drake.cell.controller.supervisor.Supervisor`)."""

    configuration: InputPort
    indication: InputPort
    arm: InputPort  # ur3.state_estimated: joint positions, then velocities
    gripper: InputPort  # rg2.state_measured: opening, rate
    grip: InputPort  # rg2.grip_detected
    speed_limit: InputPort
    stop: InputPort
    body: InputPort
    safety_mode: InputPort
    wrench: InputPort  # ur3.tcp_force: the wrist load's force, then its moment

    @staticmethod
    def declare(system: LeafSystem) -> SupervisorInputs:
        """Declare the ports on `system`, in the order they have always had."""
        return SupervisorInputs(
            configuration=system.DeclareAbstractInputPort(
                "configuration", AbstractValue.Make(CellConfiguration())
            ),
            indication=system.DeclareAbstractInputPort(
                "hri.indication", AbstractValue.Make(Indication())
            ),
            arm=system.DeclareVectorInputPort("ur3.state_estimated", 2 * N_JOINTS),
            gripper=system.DeclareVectorInputPort("rg2.state_measured", 2),
            grip=system.DeclareVectorInputPort("rg2.grip_detected", 1),
            speed_limit=system.DeclareVectorInputPort("speed_limit", BasicVector(1)),
            stop=system.DeclareVectorInputPort("safety.stop", BasicVector(1)),
            body=system.DeclareAbstractInputPort("operator.body", AbstractValue.Make(NOBODY)),
            safety_mode=system.DeclareVectorInputPort("safety.mode", BasicVector(1)),
            wrench=system.DeclareVectorInputPort("ur3.tcp_force", BasicVector(6)),
        )


class Readings:
    """The measurements of one update, read from `context` when asked for."""

    def __init__(self, inputs: SupervisorInputs, context):
        self._inputs, self._context = inputs, context

    def configuration(self) -> CellConfiguration:
        """The configuration sensor's reading: where each part is and any obstacle."""
        return self._inputs.configuration.Eval(self._context)

    def indication(self) -> Indication:
        """The operator's latest indication on the interface."""
        return self._inputs.indication.Eval(self._context)

    def arm_q(self) -> np.ndarray:
        """The arm's measured joint positions [rad]."""
        return self._inputs.arm.Eval(self._context)[:N_JOINTS]

    def opening(self) -> float:
        """The gripper's measured opening [m]."""
        return float(self._inputs.gripper.Eval(self._context)[0])

    def gripped(self) -> bool:
        """Whether the gripper detects a grip (its fingers stalled on something)."""
        return self._inputs.grip.Eval(self._context)[0] > 0.5

    def speed_limit(self) -> float:
        """The speed scale the separation monitor allows (unconnected: 1)."""
        port = self._inputs.speed_limit
        return port.Eval(self._context)[0] if port.HasValue(self._context) else 1.0

    def stop(self) -> bool:
        """Whether the robot's safety system holds the arm (unconnected: never)."""
        port = self._inputs.stop
        return port.HasValue(self._context) and port.Eval(self._context)[0] > 0.5

    def safety_mode(self) -> SafetyMode:
        """The robot's safety mode (unconnected: a protective stop while `stop`, else
        normal)."""
        port = self._inputs.safety_mode
        if port.HasValue(self._context):
            return SafetyMode(round(port.Eval(self._context)[0]))
        return SafetyMode.PROTECTIVE_STOP if self.stop() else SafetyMode.NORMAL

    def wrench(self) -> np.ndarray | None:
        """The wrist load: force [N], then moment [N·m], world frame (unconnected: None, the
        arm measures none)."""
        port = self._inputs.wrench
        return port.Eval(self._context) if port.HasValue(self._context) else None

    def body(self) -> BodySpheres:
        """The tracked operator body (unconnected: nobody)."""
        port = self._inputs.body
        return port.Eval(self._context) if port.HasValue(self._context) else NOBODY


__all__ = ["Readings", "SupervisorInputs"]
