"""The UR3's joint servo in the simulated station: PD on the commanded joint state, gravity
compensated as a UR controller does inside (simulator only).

A UR controller holds the arm with a model of its own links' weight; the plant's implicit PD
actuators stand in for the servo, and `GravityCompensation` feeds them the torque that carries
the links. The arm's gravity stays on in the plant (rather than switched off, which would be the
same motion) so that the contact problem always has the links' weight to scale its tolerance
by: with every part bolted and the arm at rest, SAP has nothing else, and a problem that small
fails to converge on round-off (seen at rest after the third bolt of Table 2's row 7).
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointActuatorIndex
from pydrake.systems.framework import BasicVector, LeafSystem


def servo_actuators(plant: MultibodyPlant, model) -> list:
    """The joint actuators of model instance `model`, in the plant's order (also before
    Finalize, when `GetJointActuatorIndices(model)` is still empty)."""
    actuators = [
        plant.get_joint_actuator(JointActuatorIndex(i)) for i in range(plant.num_actuators())
    ]
    return [a for a in actuators if a.model_instance() == model]


class GravityCompensation(LeafSystem):
    """The actuation that carries the weight of `model`'s links (and of nothing they hold),
    from the instance's measured state. Input port: `state` (the instance's q, v). Output port:
    `actuation` (one per actuator of the instance, in the plant's actuator order)."""

    def __init__(self, plant: MultibodyPlant, model):
        super().__init__()
        self._plant, self._model = plant, model
        self._context = plant.CreateDefaultContext()
        actuators = [
            plant.get_joint_actuator(index) for index in plant.GetJointActuatorIndices(model)
        ]
        self._dofs = [a.joint().velocity_start() for a in actuators]
        nq, nv = plant.num_positions(model), plant.num_velocities(model)
        self._nq = nq
        self._state = self.DeclareVectorInputPort("state", BasicVector(nq + nv))
        self.DeclareVectorOutputPort("actuation", BasicVector(len(actuators)), self._calc)

    def _calc(self, context, output) -> None:
        q = self._state.Eval(context)[: self._nq]
        self._plant.SetPositions(self._context, self._model, q)
        weight = self._plant.CalcGravityGeneralizedForces(self._context)
        output.SetFromVector(-np.asarray(weight)[self._dofs])


__all__ = ["GravityCompensation", "servo_actuators"]
