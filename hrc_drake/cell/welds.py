"""Weld constraints: what only the simulated station does to hold a part (simulator only).

A real cell holds a part by the gripper's friction and fixes it with bolts; the simulated
station welds it. Both welds are declared in the plant before it is finalized and switched on
and off by the station, never by the controller:

- a grasp weld while the fingers are closed on a part whose grasp frame is at the gripper's tcp
  (`GraspWelds`, from the commanded opening and the body poses);
- a bolt weld from the moment the simulated operator has bolted a part, at the seat the
  configuration sensor reads it in (`hrc_drake.cell.sim_operator.SimulatedOperator`).

A Drake system cannot write the plant's constraint parameters from its events, so the station's
`Simulator` monitor stops the simulation at the step where the wanted welds change and the runner
applies them (`WeldConstraints.apply`) before it advances again.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import MultibodyConstraintId
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell_models import PLATE, CellDesign
from hrc_drake.motion.poses import CellFrames, seat_pose
from hrc_drake.robot_models import GRIPPER


@dataclass(frozen=True)
class Weld:
    """A weld the station wants active: a grasp, or a bolt at a seat."""

    kind: str  # "grasp" | "bolt"
    part: str
    seat: str = ""  # bolt: the seat key (token on the plate, "<host>/row_<j>" on a host part)

    def __deepcopy__(self, memo) -> Weld:
        return self  # immutable


def _fixed_pose(plant: MultibodyPlant, model, frame: str) -> RigidTransform:
    return plant.GetFrameByName(frame, model).GetFixedPoseInBodyFrame()


def _body(plant: MultibodyPlant, model):
    return plant.get_body(plant.GetBodyIndices(model)[0])


@dataclass(frozen=True)
class WeldConstraints:
    """The declared weld constraints of every part (ids of the plant's constraints)."""

    grasps: Mapping[str, MultibodyConstraintId]
    bolts: Mapping[tuple[str, str], MultibodyConstraintId]

    @staticmethod
    def declare(
        plant: MultibodyPlant, instances: Mapping[str, object], design: CellDesign
    ) -> WeldConstraints:
        """Declare (before Finalize) a bolt weld for every seat a part may take, on the plate
        and on every host row, and a grasp weld to the gripper's tcp (with the robot)."""
        spec = design.spec
        plate = instances[PLATE]
        seats = {k: _fixed_pose(plant, plate, f"slot_{k}") for k in range(1, design.slots + 1)}
        hosts = [p for p in design.parts if spec.part(p.symbol).is_host]
        grasps, bolts = {}, {}
        for part in design.parts:
            body = _body(plant, instances[part.name])
            for token, mount, slots in spec.placements():
                if mount.part == part.symbol and mount.on == "base":
                    bolts[(part.name, token)] = plant.AddWeldConstraint(
                        _body(plant, plate), seat_pose(seats, slots), body, RigidTransform()
                    )
            mounts_on = {m.on for m in spec.mounts if m.part == part.symbol}
            for host in (h for h in hosts if h.symbol in mounts_on):
                host_model = instances[host.name]
                for j in range(1, spec.part(host.symbol).footprint + 1):
                    X_host_row = _fixed_pose(plant, host_model, f"row_{j}")
                    bolts[(part.name, f"{host.name}/row_{j}")] = plant.AddWeldConstraint(
                        _body(plant, host_model), X_host_row, body, RigidTransform()
                    )
            if GRIPPER in instances:
                tcp = plant.GetFrameByName("tcp", instances[GRIPPER])
                X_part_grasp = _fixed_pose(plant, instances[part.name], "grasp")
                grasps[part.name] = plant.AddWeldConstraint(
                    tcp.body(), tcp.GetFixedPoseInBodyFrame(), body, X_part_grasp
                )
        return WeldConstraints(grasps, bolts)

    def ids(self, welds: Iterable[Weld]) -> set[MultibodyConstraintId]:
        """The constraint ids of `welds` (a bolt at a seat that has no constraint is skipped:
        the operator cannot bolt a part where it does not fit)."""
        ids = set()
        for weld in welds:
            if weld.kind == "grasp":
                ids.add(self.grasps[weld.part])
            elif (weld.part, weld.seat) in self.bolts:
                ids.add(self.bolts[(weld.part, weld.seat)])
        return ids

    def active(self, plant: MultibodyPlant, plant_context) -> set[MultibodyConstraintId]:
        """The ids active in `plant_context`."""
        every = [*self.grasps.values(), *self.bolts.values()]
        return {cid for cid in every if plant.GetConstraintActiveStatus(plant_context, cid)}

    def apply(self, plant: MultibodyPlant, plant_context, welds: Iterable[Weld]) -> None:
        """Make exactly `welds` active in `plant_context`."""
        wanted = self.ids(welds)
        for cid in [*self.grasps.values(), *self.bolts.values()]:
            status = cid in wanted
            if plant.GetConstraintActiveStatus(plant_context, cid) != status:
                plant.SetConstraintActiveStatus(plant_context, cid, status)


class GraspWelds(LeafSystem):
    """Sim only: which parts the gripper holds, as the grasp welds stand in for friction.

    A part is welded to the gripper when the commanded opening closes below its width plus
    `release_margin` while its grasp frame is at the tcp (within `reach` and `angle`), and let go
    when the command opens past that. Input ports: `rg2.opening` (commanded, 1), `body_poses`.
    Output port: `grasps` (frozenset[Weld]). Updated every `period` seconds."""

    def __init__(
        self,
        plant: MultibodyPlant,
        frames: CellFrames,
        instances: Mapping[str, object],
        period: float,
        release_margin: float = 0.002,
        reach: float = 0.005,
        angle: float = 0.1,
    ):
        super().__init__()
        rg2 = instances[GRIPPER]
        tcp = plant.GetFrameByName("tcp", rg2)
        self._tcp = (int(tcp.body().index()), tcp.GetFixedPoseInBodyFrame())
        self._parts = {
            name: (int(_body(plant, instances[name]).index()), frames.grasps[name])
            for name in frames.design.instance_names
        }
        self._widths = dict(frames.widths)
        self._margin, self._reach, self._angle = release_margin, reach, angle
        self._command = self.DeclareVectorInputPort("rg2.opening", BasicVector(1))
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._held = self.DeclareAbstractState(AbstractValue.Make(frozenset()))
        self.DeclareStateOutputPort("grasps", self._held)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def _at_tcp(self, poses, part: str) -> bool:
        body, X_part_grasp = self._parts[part]
        X_W_tcp = poses[self._tcp[0]] @ self._tcp[1]
        X_rel = X_W_tcp.InvertAndCompose(poses[body] @ X_part_grasp)
        turn = X_rel.rotation().ToAngleAxis().angle()
        # The parts are symmetric under a half turn about the approach axis.
        aligned = min(turn, abs(turn - math.pi)) <= self._angle
        return bool(np.linalg.norm(X_rel.translation()) <= self._reach and aligned)

    def _update(self, context, state) -> None:
        command = float(self._command.Eval(context)[0])
        poses = self._poses.Eval(context)
        held = {weld.part for weld in context.get_abstract_state(self._held).get_value()}
        for part, width in self._widths.items():
            closed = command < width + self._margin
            if part in held and not closed:
                held.discard(part)
            elif part not in held and closed and not held and self._at_tcp(poses, part):
                held.add(part)
        state.get_mutable_abstract_state(self._held).set_value(
            frozenset(Weld("grasp", part) for part in held)
        )


__all__ = ["GraspWelds", "Weld", "WeldConstraints"]
