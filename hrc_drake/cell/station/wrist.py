"""The UR3's wrist load in the simulated station: what the force/torque sensor in a UR e-Series's
tool flange reports (RTDE's `actual_TCP_force`), from the plant (simulator only).

The gripper is welded to the arm's `tool0`; the weld carries every load the gripper meets from
outside — the weight of a part it holds, a part pressed onto something, a finger against the
plate — and the gripper's own inertia as the arm moves it. The plant reports the weld's reaction
force (`get_reaction_forces_output_port`); its opposite is the load the tool meets. The gripper's
own weight is not in it (the station switches the gripper's gravity off, as a UR controller
takes its configured payload off the reading).

`ur3.tcp_force` (6): that load's force [N], then its moment [N·m] about the `tcp` point, both in
the world frame (the arm's base frame: the UR3 stands at the world origin), signed as the tool
meets it: a part pushed up against the fingers reads +z, one hanging in them -z (its weight).
Through a sensor model with `sensors:` (`hrc_drake.cell.station.sensors`, key `wrench`).
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.motion.scene import TCP


class TcpForce(LeafSystem):
    """The load the tool meets (see the module docstring), from the reaction at the weld of
    `gripper`'s base to the arm. Inputs: `reaction_forces` and `body_poses` (the plant's).
    Output: `tcp_force` (6: force [N], moment about the tcp [N·m], world frame)."""

    def __init__(self, plant: MultibodyPlant, gripper):
        super().__init__()
        base = plant.GetBodyByName("rg2_base", gripper)
        joints = [plant.get_joint(j) for j in plant.GetJointIndices(gripper)]
        weld = next(
            (j for j in joints if j.child_body().index() == base.index()),
            None,
        )
        if weld is None:
            raise ValueError("the gripper's base is not jointed to the arm: no wrist load to read")
        self._joint = int(weld.index())
        self._base = int(base.index())
        # The weld's frame on the gripper's base and the tcp, both fixed in that body.
        self._X_BJ = weld.frame_on_child().GetFixedPoseInBodyFrame()
        tcp = plant.GetFrameByName(TCP, gripper)
        if tcp.body().index() != base.index():
            raise ValueError(f"the gripper's {TCP} frame is not on its base body")
        self._p_BT = tcp.GetFixedPoseInBodyFrame().translation()
        self._reactions = self.DeclareAbstractInputPort(
            "reaction_forces", AbstractValue.Make([SpatialForce()])
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self.DeclareVectorOutputPort("tcp_force", BasicVector(6), self._calc)

    def _calc(self, context, output) -> None:
        # The reaction is the force on the child (the gripper) by the parent (the arm), at the
        # weld's frame, in that frame; the tool meets its opposite.
        F_J = self._reactions.Eval(context)[self._joint]
        X_WB = self._poses.Eval(context)[self._base]
        # `multiply`: pydrake's `@` goes through a Python wrapper first.
        X_WJ = X_WB.multiply(self._X_BJ)
        F_W = F_J.Rotate(X_WJ.rotation())
        p_JT_W = X_WB.multiply(self._p_BT) - X_WJ.translation()
        load = F_W.Shift(p_JT_W)
        output.SetFromVector(-np.concatenate([load.translational(), load.rotational()]))


def add_tcp_force(builder, plant: MultibodyPlant, gripper):
    """The wrist load system (`ur3_tcp_force`) wired to the plant; its output port."""
    wrist = builder.AddNamedSystem("ur3_tcp_force", TcpForce(plant, gripper))
    builder.Connect(plant.get_reaction_forces_output_port(), wrist.GetInputPort("reaction_forces"))
    builder.Connect(plant.get_body_poses_output_port(), wrist.GetInputPort("body_poses"))
    return wrist.GetOutputPort("tcp_force")


__all__ = ["TcpForce", "add_tcp_force"]
