"""The robot's effective mass at a point of its shapes along a direction, for ISO/TS 15066 Annex
A's energy-transfer model (`hrc_drake.cell.contact_limits`): m_u = 1 / (uᵀ J M⁻¹ Jᵀ u), with M
the arm's mass matrix at the measured pose and J the point's translational Jacobian
(shared/reference/safety-and-devices.md), better than the standard's M/2 + m_L for a given pose.

From the MultibodyPlant of a `RobotEnvelope`: the arm's six joints move, the gripper's linkage is
held (it is position-controlled), and the carried part's spatial inertia rides on the tcp's body
where the gripper holds it (`RobotEnvelope.held_poses`). A point the arm cannot move along u (the
fixed base, a singular direction) has an infinite effective mass.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from hrc_drake.cell.robot_envelope import Primitives, RobotEnvelope
from hrc_drake.robot_names import GRIPPER, UR3

_TINY = 1e-12  # an inverse effective mass below this is a direction the arm cannot move along


class EffectiveMass:
    """Effective masses of the robot of `envelope` (which it poses: not thread-safe)."""

    def __init__(self, envelope: RobotEnvelope):
        self.envelope = envelope
        plant = envelope.plant
        self._parts = {
            name: plant.get_body(plant.GetBodyIndices(plant.GetModelInstanceByName(name))[0])
            for name in envelope.held_poses
        }
        moving = [
            plant.get_body(index)
            for model in (plant.GetModelInstanceByName(UR3), plant.GetModelInstanceByName(GRIPPER))
            for index in plant.GetBodyIndices(model)
        ]
        fixed = len(envelope.links)
        # Annex A's own estimate of the robot, half its moving mass (the payload added in
        # `floor`): the plant leaves out the joints' reflected rotor inertia, which only adds to
        # m_u, so the model's figure is never taken below it.
        self.half_moving_mass = 0.5 * sum(
            b.default_mass() for b in moving if envelope.link_of(b) < fixed
        )

    def floor(self, carrying: str | None) -> float:
        """Annex A's M/2 + m_L [kg]: half the arm's and gripper's moving mass plus the part's."""
        part = 0.0 if carrying is None else self._parts[carrying].default_mass()
        return self.half_moving_mass + part

    def _arm_mass_matrix(self, carrying: str | None) -> np.ndarray:
        """The arm joints' mass matrix at the context's pose, with the part held."""
        env = self.envelope
        plant, context, arm = env.plant, env.context, env.arm_velocities
        mass = plant.CalcMassMatrix(context)[np.ix_(arm, arm)]
        if carrying is None:
            return mass
        if carrying not in self._parts:
            raise KeyError(f"no part {carrying!r}; the parts are {sorted(self._parts)}")
        X_B_part = env.held_poses[carrying]
        body = env.tcp_body
        jacobian = plant.CalcJacobianSpatialVelocity(
            context,
            JacobianWrtVariable.kV,
            body.body_frame(),
            X_B_part.translation(),
            plant.world_frame(),
            plant.world_frame(),
        )[:, arm]
        R_WB = plant.EvalBodyPoseInWorld(context, body).rotation()
        inertia = self._parts[carrying].default_spatial_inertia()  # about the part's origin
        spatial = inertia.ReExpress(R_WB @ X_B_part.rotation()).CopyToFullMatrix6()
        return mass + jacobian.T @ spatial @ jacobian

    def along(
        self,
        q: np.ndarray,
        opening: float | None,
        carrying: str | None,
        shapes: Primitives,
        rows: np.ndarray,
        points: np.ndarray,
        directions: np.ndarray,
    ) -> np.ndarray:
        """The effective mass [kg] of the robot at arm positions `q` and gripper `opening`,
        holding `carrying`, at each world point `points[i]` (k×3) on shape `rows[i]` of
        `shapes`, along the unit `directions[i]` (k×3), never below `floor`; inf where the arm
        cannot move it so."""
        env = self.envelope
        R_WB, p_WB = env.pose(q, opening)  # sets the context's pose
        plant, context = env.plant, env.context
        inverse_mass = np.linalg.inv(self._arm_mass_matrix(carrying))
        body_rows = shapes.body[np.asarray(rows, dtype=int)]
        out = np.full(len(body_rows), np.inf)
        for row in np.unique(body_rows):
            at = np.flatnonzero(body_rows == row)
            p_B = (points[at] - p_WB[row]) @ R_WB[row]  # R_BW (p_W − p_WB), row by row
            jacobian = plant.CalcJacobianTranslationalVelocity(
                context,
                JacobianWrtVariable.kV,
                env.bodies[row].body_frame(),
                p_B.T,
                plant.world_frame(),
                plant.world_frame(),
            )[:, env.arm_velocities].reshape(len(at), 3, -1)
            along = np.einsum("kj,kja->ka", directions[at], jacobian)
            inverse = np.einsum("ka,ab,kb->k", along, inverse_mass, along)
            out[at] = np.where(inverse > _TINY, 1.0 / np.maximum(inverse, _TINY), np.inf)
        return np.maximum(out, self.floor(carrying))


__all__ = ["EffectiveMass"]
