"""The built station, `CellStation`, and what a run does with it beside its ports: switch the
bolts' welds as the simulated operator bolts (`welds_changed`, `apply_welds`), place parts by
hand for an operator who did a task, slide a part in the fingers (a no-seat fault), and make the
default context with the arm held. Built by `hrc_drake.cell.station.build.make_cell_station`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    Meshcat,
    MeshcatVisualizer,
)
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.plant import (
    MultibodyPlant,
)
from pydrake.systems.framework import Context, Diagram

from hrc_drake.cell.ports import CellConfiguration, PartStatus, placement_transform
from hrc_drake.cell.station.camera import CAMERA_SYSTEM
from hrc_drake.cell.station.faults import FaultInjector
from hrc_drake.cell.station.sim_operator import SimulatedOperator
from hrc_drake.cell.station.welds import Bolts, Weld
from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.messages import Prompt
from hrc_drake.motion.poses import CellFrames, layout_poses, part_pose
from hrc_drake.obstacle_models import DEBRIS, DEBRIS_PARK
from hrc_drake.robot_models import rg2_opening
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.tokens import UNDO


@dataclass(frozen=True)
class CellStation:
    """The built station (see the module docstring for its ports)."""

    diagram: Diagram
    plant: MultibodyPlant
    scene_graph: object
    scenario: Scenario
    design: CellDesign
    frames: CellFrames
    instances: Mapping[str, object]
    bolts: Bolts
    meshcat: Meshcat | None = None
    visualizer: MeshcatVisualizer | None = None
    injector: FaultInjector | None = None  # with the robot
    operator: SimulatedOperator | None = None

    @property
    def has_robot(self) -> bool:
        """True if the UR3 and the gripper are in the cell."""
        return UR3 in self.instances

    def part_body(self, part: str):
        """The body of the part instance `part` (e.g. ``oval_flange_1``)."""
        if part not in self.design.instance_names:
            raise KeyError(
                f"unknown part {part!r}; the parts are {', '.join(self.design.instance_names)}"
            )
        return self.plant.get_body(self.plant.GetBodyIndices(self.instances[part])[0])

    def configuration(self, context: Context) -> CellConfiguration:
        """Where the parts truly are in the root `context`: the contact sensor's reading, the
        simulator's ground truth (the `configuration` port's, or `sim.configuration` beside a
        camera's, `sensors: {configuration: camera}`)."""
        station_context = self.diagram.GetMyContextFromRoot(context)
        name = "sim.configuration" if self.diagram.HasOutputPort("sim.configuration") else None
        return self.diagram.GetOutputPort(name or "configuration").Eval(station_context)

    def camera_score(self, context: Context):
        """The camera's verdicts scored against the contact sensor's so far, in the root
        `context` (`hrc_drake.cell.station.camera_score.CameraScore`); None without a camera."""
        if not self.diagram.HasSubsystemNamed(CAMERA_SYSTEM):
            return None
        camera = self.diagram.GetSubsystemByName(CAMERA_SYSTEM)
        return camera.score(camera.GetMyContextFromRoot(context))

    def safety_function_state(self, context: Context):
        """The safety function's `SafetyFunctionState` in the root `context` (None: no robot)."""
        if not self.diagram.HasSubsystemNamed("safety_function"):
            return None
        function = self.diagram.GetSubsystemByName("safety_function")
        return function.state(function.GetMyContextFromRoot(context))

    def placement_poses(self, placements: Mapping[str, str]) -> dict[str, RigidTransform]:
        """World poses of parts seated as `placements` says (part instance -> token or tray)."""
        return layout_poses(self.frames, placements)

    def wanted_welds(self, context: Context) -> frozenset[Weld]:
        """The bolts the simulated operator has put in (those that take), in the root
        `context`."""
        station_context = self.diagram.GetMyContextFromRoot(context)
        return frozenset(self.diagram.GetOutputPort("sim.welds").Eval(station_context))

    def welds_changed(self, context: Context, applied: frozenset[Weld]) -> bool:
        """Whether the wanted welds differ from `applied` (what `apply_welds` returned last),
        or a fault wants a part moved: a `Simulator` monitor returns ReachedTermination then,
        and the runner applies them."""
        return (
            self.wanted_welds(context) != applied
            or bool(self._pending_shifts(context))
            or bool(self._hand_placements(context))
        )

    def apply_welds(self, context: Context) -> frozenset[Weld]:
        """Make the wanted bolts the ones that hold in the root `context` (a new one fixes its
        part where it sits now), and move the parts the no-seat faults slide in the fingers;
        returns the bolts."""
        plant_context = self.plant.GetMyMutableContextFromRoot(context)
        self._place_by_hand(context, plant_context)
        wanted = self.wanted_welds(context)
        filters = self.scene_graph.collision_filter_manager(
            self.scene_graph.GetMyMutableContextFromRoot(context)
        )
        self.bolts.apply(plant_context, wanted, filters)
        for index, fault in self._pending_shifts(context):
            self._slide_in_fingers(plant_context, fault.offset)
            self.injector.mark_shifted(self.injector.GetMyMutableContextFromRoot(context), index)
        return wanted

    def _hand_placements(self, context: Context) -> tuple:
        if self.operator is None:
            return ()
        return self.operator.placements(self.operator.GetMyContextFromRoot(context))

    def _place_by_hand(self, context: Context, plant_context) -> None:
        """Put the parts of the tasks the operator did by hand where the task puts them, at
        rest (a placement: its seat, on the plate or where the host part measured under it
        sits; an undo: its tray home), and tell the operator, whose bolt then takes. The
        operator also puts back in their tray homes the other loose parts (neither seated nor
        held nor home: what a falling part knocked out of the tray), so that the robot finds
        them where it picks them."""
        operator_context = (
            self.operator.GetMyMutableContextFromRoot(context) if self.operator else None
        )
        for task, part, state in self._hand_placements(context):
            self._clear_debris(context, plant_context)
            config = self.configuration(context)
            part = part or self._part_for(config, task, state)
            if part:
                body = self.part_body(part)
                X = self.frames.homes[part] if task == UNDO else self._seat_by_hand(config, task)
                self.plant.SetFreeBodyPose(plant_context, body, X)
                self.plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity.Zero())
                self._handled_by_hand(context, part)
            for other, placement in config.placements:
                if other != part and placement.status in (
                    PartStatus.TRANSIT,
                    PartStatus.MISPLACED,
                ):
                    body = self.part_body(other)
                    self.plant.SetFreeBodyPose(plant_context, body, self.frames.homes[other])
                    self.plant.SetFreeBodySpatialVelocity(
                        plant_context, body, SpatialVelocity.Zero()
                    )
                    self._handled_by_hand(context, other)
            self.operator.placed(operator_context, part)

    def _handled_by_hand(self, context: Context, part: str) -> None:
        """Tell the camera, if the station has one, that the operator moved `part` by hand."""
        if self.diagram.HasSubsystemNamed(CAMERA_SYSTEM):
            camera = self.diagram.GetSubsystemByName(CAMERA_SYSTEM)
            camera.part_handled(camera.GetMyMutableContextFromRoot(context), part)

    def _clear_debris(self, context: Context, plant_context) -> None:
        """The operator, doing a task by hand, takes any debris out of the pocket first (its
        carriage parks at once, out of the part's way)."""
        if self.injector is None or DEBRIS not in self.instances:
            return
        if self.injector.clear_debris(self.injector.GetMyMutableContextFromRoot(context)):
            model = self.instances[DEBRIS]
            self.plant.SetPositions(plant_context, model, list(DEBRIS_PARK))
            self.plant.SetVelocities(plant_context, model, [0.0] * len(DEBRIS_PARK))

    def _part_for(self, config: CellConfiguration, task: str, state: tuple[str, ...]) -> str:
        """The part the operator takes for `task` when the robot chose none: for an undo the
        one at the last token; else the lowest-numbered of the task's kind in the tray (""
        if none)."""
        if task == UNDO:
            at = state[-1] if state else None
            return next((i for i, t in config.layout().items() if t == at), "")
        symbol = self.design.spec.placement(task).part
        free = [
            i
            for i in self.design.instance_names
            if self.design.symbol_of(i) == symbol and config.placement(i).status == PartStatus.TRAY
        ]
        return min(free, default="")

    def _seat_by_hand(self, config: CellConfiguration, task: str) -> RigidTransform:
        """Where a part put in place by hand for `task` sits: its seat on the plate, or its
        row on the host part as the host measurably sits (bolted where it came to rest, not at
        its nominal seat)."""
        tokens = sorted(config.tokens())
        X_nominal = part_pose(self.frames, task, tokens)
        host = self.design.spec.placement(task).host
        if host is None:
            return X_nominal
        for instance, token in config.layout().items():
            placement = self.design.spec.placement(token)
            if (
                placement.part == host
                and placement.host is None
                and config.placement(instance).pose
            ):
                X_host = part_pose(self.frames, token, tokens)
                if set(self.design.spec.placement(task).slots) <= set(placement.slots):
                    X_measured = placement_transform(config.placement(instance))
                    return X_measured @ X_host.inverse() @ X_nominal
        return X_nominal

    def _pending_shifts(self, context: Context) -> list:
        if not self.scenario.faults or self.injector is None:
            return []
        return self.injector.pending_shifts(self.injector.GetMyContextFromRoot(context))

    def _slide_in_fingers(self, plant_context, offset: float) -> None:
        """Move the part between the fingers `offset` along the pads (across the fingers'
        closing axis and the approach axis), as a part that slid as the fingers closed."""
        plant, rg2 = self.plant, self.instances[GRIPPER]
        tcp = plant.GetFrameByName("tcp", rg2).CalcPoseInWorld(plant_context)
        fingers = [
            plant.EvalBodyPoseInWorld(plant_context, plant.get_body(index)).translation()
            for index in plant.GetBodyIndices(rg2)
            if plant.get_body(index).name().endswith("finger")
        ]
        closing = (fingers[1] - fingers[0]) / np.linalg.norm(fingers[1] - fingers[0])
        along = np.cross(tcp.rotation().col(2), closing)
        held = min(
            self.design.instance_names,
            key=lambda name: np.linalg.norm(
                (
                    plant.EvalBodyPoseInWorld(plant_context, self.part_body(name))
                    @ self.frames.grasps[name]
                ).translation()
                - tcp.translation()
            ),
        )
        body = self.part_body(held)
        X = plant.EvalBodyPoseInWorld(plant_context, body)
        plant.SetFreeBodyPose(
            plant_context, body, RigidTransform(X.rotation(), X.translation() + offset * along)
        )

    def create_default_context(self) -> Context:
        """A root context with the bolts as wanted (none at the start), nothing on the
        operator's interface and, with the robot, its command inputs holding the initial posture
        and opening at the scenario's grip force (so it can be simulated alone)."""
        context = self.diagram.CreateDefaultContext()
        if self.has_robot:
            self.hold_robot(context)
        self.diagram.GetInputPort("hri.prompt").FixValue(context, Prompt())
        self.apply_welds(context)
        return context

    def hold_robot(
        self, context: Context, opening: float | None = None, force: float | None = None
    ) -> None:
        """Fix the robot command inputs of the root `context` to hold the arm where it is,
        fingers at `opening` (default: as they are) with the grip `force` (default: the
        scenario's `station.rg2.grip_force`)."""
        plant_context = self.plant.GetMyContextFromRoot(context)
        q = self.plant.GetPositions(plant_context, self.instances[UR3])
        self.diagram.GetInputPort("ur3.position").FixValue(context, q)
        self.diagram.GetInputPort("ur3.velocity").FixValue(context, np.zeros_like(q))
        if opening is None:
            opening = rg2_opening(self.plant, plant_context, self.instances[GRIPPER])
        self.diagram.GetInputPort("rg2.opening").FixValue(context, [opening])
        if force is None:
            force = self.scenario.station.rg2.grip_force
        self.diagram.GetInputPort("rg2.force").FixValue(context, [force])


__all__ = ["CellStation"]
