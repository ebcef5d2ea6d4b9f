"""Planning scenes: the cell as a MultibodyPlant + SceneGraph for one layout of the parts.

A planning scene has no simulation: every part is welded where the layout puts it (the tray home,
a seat, a measured pose where it lies loose, or the gripper's tcp at its grasp pose, so a carried
part is robot geometry), the gripper's linkage is welded at one opening, and the only degrees of
freedom are the six UR3 joints.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import (
    Box,
    Capsule,
    CollisionFilterDeclaration,
    Convex,
    Cylinder,
    Ellipsoid,
    GeometrySet,
    Mesh,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell_models import CellDesign, add_cell_models, check_cell_models
from hrc_drake.motion.poses import (
    CellFrames,
    part_pose,
    pose_from_values,
    pose_values,
    tcp_in_part,
)
from hrc_drake.obstacle_models import add_fixed_obstacle, far_below
from hrc_drake.rg2_kinematics import joint_angles
from hrc_drake.robot_models import RG2_JOINTS, RG2_MAX_OPENING, RG2_OPENING_AXIS
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS
from hrc_drake.workpiece_sdf import PLATE, TRAY

ROBOT = UR3
TCP = "tcp"
MAX_OPENING = RG2_MAX_OPENING
# Wrist links sit right against the gripper mount; their capsules may touch it (calibration).
_WRIST_LINKS = ("wrist_1_link", "wrist_2_link", "wrist_3_link")


def part_body(plant: MultibodyPlant, instance: str):
    """The body of a one-body part model."""
    model = plant.GetModelInstanceByName(instance)
    bodies = plant.GetBodyIndices(model)
    if len(bodies) != 1:
        raise ValueError(f"part model {instance!r} has {len(bodies)} bodies; expected one")
    return plant.get_body(bodies[0])


def _weld_linkage(plant: MultibodyPlant) -> dict[str, tuple[FixedOffsetFrame, np.ndarray]]:
    """Replace each joint of the gripper's linkage by a weld to a frame whose pose (a turn by the
    joint's angle about its axis) sets the opening: joint name -> (frame, axis)."""
    gripper = plant.GetModelInstanceByName(GRIPPER)
    # The models' only constraints are the linkage's couplers, which the welds replace.
    for constraint in plant.GetConstraintIds():
        plant.RemoveConstraint(constraint)
    for index in plant.GetJointActuatorIndices():  # (per instance: empty before Finalize)
        actuator = plant.get_joint_actuator(index)
        if actuator.model_instance() == gripper:
            plant.RemoveJointActuator(actuator)
    welds = {}
    for name in RG2_JOINTS:
        joint = plant.GetJointByName(name, gripper)
        parent, child = joint.frame_on_parent(), joint.frame_on_child()
        axis = np.asarray(joint.revolute_axis())
        plant.RemoveJoint(joint)
        frame = plant.AddFrame(FixedOffsetFrame(f"{name}_weld", parent, RigidTransform()))
        plant.WeldFrames(frame, child, RigidTransform())
        welds[name] = (frame, axis)
    return welds


@dataclass(frozen=True)
class Layout:
    """Where each part is in a scene, hashable (the scene cache key).

    Attributes:
        placed: (instance, token) for each part on the plate or a host; the rest are in the tray
            unless loose.
        carried: the instance welded to the gripper at its grasp pose, if any.
        opening: finger opening [m] (between the finger insides).
        loose: (instance, (x, y, z, qw, qx, qy, qz)) for each part lying where it was measured
            (dropped, not seated: anywhere on the table, plate, tray or other parts), sorted.
        obstacle: the world pose (x, y, z, qw, qx, qy, qz) of the temporary obstacle the cell
            measures (`hrc_drake.obstacle_models`), or () for none.
    """

    placed: tuple[tuple[str, str], ...]
    carried: str | None
    opening: float
    loose: tuple[tuple[str, tuple[float, ...]], ...] = ()
    obstacle: tuple[float, ...] = ()

    @staticmethod
    def of(
        assignment: Mapping[str, str],
        carried: str | None,
        opening: float,
        loose: Mapping[str, RigidTransform] | None = None,
        obstacle: tuple[float, ...] = (),
    ) -> Layout:
        """From token -> instance; a carried instance is taken out of `assignment`. `loose`:
        instance -> X_W_part of parts lying where they were measured (neither placed nor
        carried); `obstacle`: the measured obstacle's 7 pose values, or ()."""
        placed = tuple(sorted((inst, tok) for tok, inst in assignment.items() if inst != carried))
        lying = tuple(sorted((inst, pose_values(X)) for inst, X in (loose or {}).items()))
        clash = {inst for inst, _ in lying} & ({inst for inst, _ in placed} | {carried})
        if clash:
            raise ValueError(
                f"{sorted(clash)[0]} is loose and also placed or carried; a part is in one place"
            )
        if obstacle and len(obstacle) != 7:
            raise ValueError(f"an obstacle pose of {len(obstacle)} values; give 7 (or none)")
        return Layout(placed, carried, round(float(opening), 6), lying, tuple(obstacle))

    @property
    def configuration(self) -> frozenset[str]:
        """The tokens in place."""
        return frozenset(tok for _, tok in self.placed)


class SceneModel:
    """The cell's diagram with one part (or none) welded to the gripper.

    Everything else that a layout changes is a parameter: each other part is welded to a
    world-fixed frame, each link of the gripper's linkage to a frame on its parent, whose poses
    a PlanningScene sets in its own context. So one parse serves every layout with the same
    carried part.
    """

    def __init__(self, frames: CellFrames, carried: str | None):
        self.frames = frames
        self.carried = carried
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
        add_cell_models(plant, frames.design)
        self.linkage = _weld_linkage(plant)
        self.part_frames: dict[str, FixedOffsetFrame] = {}
        world = plant.world_frame()
        for instance in frames.design.instance_names:
            body = part_body(plant, instance)
            if instance == carried:
                X_tcp_part = frames.grasps[instance].inverse()
                plant.WeldFrames(self._tcp_frame(plant), body.body_frame(), X_tcp_part)
                continue
            frame = plant.AddFrame(
                FixedOffsetFrame(f"{instance}_pose", world, frames.homes[instance])
            )
            plant.WeldFrames(frame, body.body_frame(), RigidTransform())
            self.part_frames[instance] = frame
        self.obstacle_frame = add_fixed_obstacle(plant)
        plant.Finalize()
        ur3 = plant.GetModelInstanceByName(ROBOT)
        starts = [plant.GetJointByName(j, ur3).position_start() for j in UR3_JOINTS]
        if plant.num_positions() != len(UR3_JOINTS) or starts != list(range(len(UR3_JOINTS))):
            raise ValueError(
                f"planning plant has {plant.num_positions()} positions, UR3 joints at {starts}; "
                f"expected exactly {UR3_JOINTS} in that order (is a part left free?)"
            )
        self.plant = plant
        self.scene_graph = scene_graph
        self._filter_permanent()
        self.diagram = builder.Build()
        self.tcp_frame = self._tcp_frame(plant)
        self.robot_bodies = {
            int(b)
            for name in (ROBOT, GRIPPER)
            for b in plant.GetBodyIndices(plant.GetModelInstanceByName(name))
        }
        if carried is not None:
            self.robot_bodies.add(int(part_body(plant, carried).index()))

    @staticmethod
    def _tcp_frame(plant: MultibodyPlant):
        return plant.GetFrameByName(TCP, plant.GetModelInstanceByName(GRIPPER))

    def geometries(self, instance: str) -> GeometrySet:
        """Collision geometries of every body of a model instance."""
        plant = self.plant
        model = plant.GetModelInstanceByName(instance)
        bodies = [plant.get_body(b) for b in plant.GetBodyIndices(model)]
        ids = [g for b in bodies for g in plant.GetCollisionGeometriesForBody(b)]
        return GeometrySet(ids)

    def _body_geometries(self, model: str, names: Iterable[str]) -> GeometrySet:
        plant = self.plant
        instance = plant.GetModelInstanceByName(model)
        ids = [
            g
            for n in names
            if plant.HasBodyNamed(n, instance)
            for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName(n, instance))
        ]
        return GeometrySet(ids)

    def _filter_permanent(self) -> None:
        manager = self.scene_graph.collision_filter_manager()
        declaration = CollisionFilterDeclaration().ExcludeBetween(
            self._body_geometries(ROBOT, _WRIST_LINKS), self.geometries(GRIPPER)
        )
        if self.carried is not None:
            # The carried part touches the fingers that hold it.
            declaration.ExcludeBetween(self.geometries(self.carried), self.geometries(GRIPPER))
        manager.Apply(declaration)


class PlanningScene:
    """The cell in one layout, with its own diagram context (the optimisers' collision queries)."""

    def __init__(self, model: SceneModel, layout: Layout):
        if model.carried != layout.carried:
            raise ValueError(f"scene model carries {model.carried}, layout {layout.carried}")
        self.model = model
        self.layout = layout
        self.plant = model.plant
        self.scene_graph = model.scene_graph
        self.tcp_frame = model.tcp_frame
        self.context = model.diagram.CreateDefaultContext()
        self.plant_context = self.plant.GetMyMutableContextFromRoot(self.context)
        self.sg_context = self.scene_graph.GetMyMutableContextFromRoot(self.context)
        for name, angle in joint_angles(min(max(layout.opening, 0.0), MAX_OPENING)).items():
            frame, axis = model.linkage[name]
            R = RotationMatrix(AngleAxis(angle, axis))
            frame.SetPoseInParentFrame(self.plant_context, RigidTransform(R))
        placed = dict(layout.placed)
        loose = {instance: pose_from_values(values) for instance, values in layout.loose}
        tokens = layout.configuration
        frames = model.frames
        for instance, frame in model.part_frames.items():
            if instance in loose:
                X_W_part = loose[instance]
            elif instance in placed:
                X_W_part = part_pose(frames, placed[instance], tokens)
            else:
                X_W_part = frames.homes[instance]
            frame.SetPoseInParentFrame(self.plant_context, X_W_part)
        X_W_obstacle = pose_from_values(layout.obstacle) if layout.obstacle else far_below()
        model.obstacle_frame.SetPoseInParentFrame(self.plant_context, X_W_obstacle)
        self._transient: list = []

    def geometries(self, instance: str) -> GeometrySet:
        """Collision geometries of every body of a model instance."""
        return self.model.geometries(instance)

    def set_allowed_contacts(self, pairs: Iterable[tuple[str, str]]) -> None:
        """Ignore collisions between these model instances until the next call.

        Used near the grasp and place instants: the gripper around the part it grasps, the
        carried part on its seat or host, or in its tray home.
        """
        manager = self.scene_graph.collision_filter_manager(self.sg_context)
        for declaration_id in self._transient:
            manager.RemoveDeclaration(declaration_id)
        self._transient = []
        pairs = tuple(pairs)
        if pairs:
            declaration = CollisionFilterDeclaration()
            for a, b in pairs:
                declaration.ExcludeBetween(self.geometries(a), self.geometries(b))
            self._transient.append(manager.ApplyTransient(declaration))

    def near(self, instance: str, others: Iterable[str], distance: float) -> tuple[str, ...]:
        """The model instances among `others` with a collision geometry within `distance` of one
        of `instance`'s (what a part lies on or against), in the order given.

        Pairwise, regardless of collision filters (parts welded to the world are filtered
        against each other); a shape pair the query cannot measure counts as near."""
        query = self.scene_graph.get_query_output_port().Eval(self.sg_context)
        inspector = query.inspector()
        mine = inspector.GetGeometryIds(self.geometries(instance))

        def gap(a, b) -> float:
            try:
                return query.ComputeSignedDistancePairClosestPoints(a, b).distance
            except RuntimeError:  # an unsupported shape pair: assume it touches
                return -np.inf

        return tuple(
            other
            for other in others
            if any(
                gap(a, b) < distance
                for a in mine
                for b in inspector.GetGeometryIds(self.geometries(other))
            )
        )

    def set_positions(self, q: np.ndarray) -> None:
        """Put the UR3 at q."""
        self.plant.SetPositions(self.plant_context, q)

    def tcp_pose(self, q: np.ndarray) -> RigidTransform:
        """X_W_tcp at q."""
        self.set_positions(q)
        return self.tcp_frame.CalcPoseInWorld(self.plant_context)

    def min_distance(self, q: np.ndarray, max_distance: float = 0.1) -> tuple[float, str]:
        """Smallest signed distance between the robot (+ carried part) and anything else at q.

        Returns (distance, "a vs b" with body names); (max_distance, "") when nothing is closer.
        """
        self.set_positions(q)
        query = self.scene_graph.get_query_output_port().Eval(self.sg_context)
        inspector = query.inspector()
        best, pair = max_distance, ""
        for p in query.ComputeSignedDistancePairwiseClosestPoints(max_distance):
            if p.distance >= best:
                continue
            body_a = self.plant.GetBodyFromFrameId(inspector.GetFrameId(p.id_A))
            body_b = self.plant.GetBodyFromFrameId(inspector.GetFrameId(p.id_B))
            robot = self.model.robot_bodies
            if int(body_a.index()) not in robot and int(body_b.index()) not in robot:
                continue
            best, pair = (
                p.distance,
                f"{_scoped(self.plant, body_a)} vs {_scoped(self.plant, body_b)}",
            )
        return best, pair


def _scoped(plant: MultibodyPlant, body) -> str:
    return f"{plant.GetModelInstanceName(body.model_instance())}::{body.name()}"


def shape_support(shape, direction: np.ndarray) -> float:
    """max over the shape of direction · p, p in the shape's frame (direction a unit vector)."""
    d = np.asarray(direction, dtype=float)
    if isinstance(shape, Box):
        return float(np.abs(d) @ (0.5 * np.array([shape.width(), shape.depth(), shape.height()])))
    if isinstance(shape, Sphere):
        return shape.radius()
    if isinstance(shape, Cylinder):
        return shape.radius() * float(np.hypot(d[0], d[1])) + 0.5 * shape.length() * abs(d[2])
    if isinstance(shape, Capsule):
        return shape.radius() + 0.5 * shape.length() * abs(d[2])
    if isinstance(shape, Ellipsoid):
        return float(np.linalg.norm(np.array([shape.a(), shape.b(), shape.c()]) * d))
    if isinstance(shape, Convex | Mesh):
        vertices = np.asarray(shape.GetConvexHull().vertices())
        return float(np.max(np.asarray(vertices).reshape(-1, 3) @ d))
    raise TypeError(f"no support function for {type(shape).__name__}")


def load_cell_frames(design: CellDesign) -> CellFrames:
    """Read seat, tray and part frames (and the parts' grasp widths and tcp poses) from the
    cell's models."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    add_cell_models(plant, design)
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    return read_cell_frames(plant, scene_graph, plant.GetMyContextFromRoot(context), design)


def read_cell_frames(
    plant: MultibodyPlant, scene_graph, plant_context, design: CellDesign
) -> CellFrames:
    """The cell's frames in a finalized plant holding `design`'s models (CellModelError if the
    models do not fit the spec). Grasp widths need the gripper; without it they are empty, and
    each part's tcp pose is its `grasp` frame."""
    check_cell_models(plant, scene_graph, design)

    def world_pose(model: str, frame: str) -> RigidTransform:
        instance = plant.GetModelInstanceByName(model)
        return plant.GetFrameByName(frame, instance).CalcPoseInWorld(plant_context)

    seats = {k: world_pose(PLATE, f"slot_{k}") for k in range(1, design.slots + 1)}
    homes, rows, grasps, widths = {}, {}, {}, {}
    has_gripper = plant.HasModelInstanceNamed(GRIPPER)
    finger_axis = _finger_axis_in_tcp(plant, plant_context) if has_gripper else None
    inspector = scene_graph.model_inspector()
    for instance in design.instance_names:
        homes[instance] = world_pose(TRAY, f"home_{instance}")
        model = plant.GetModelInstanceByName(instance)
        body = part_body(plant, instance)
        X_part_grasp = plant.GetFrameByName("grasp", model).GetFixedPoseInBodyFrame()
        grasps[instance] = X_part_grasp
        part = design.spec.part(design.symbol_of(instance))
        if part.is_host and part.symbol not in rows:
            rows[part.symbol] = {
                j: plant.GetFrameByName(f"row_{j}", model).GetFixedPoseInBodyFrame()
                for j in range(1, part.footprint + 1)
            }
        if finger_axis is None:
            continue
        axis_part = X_part_grasp.rotation() @ finger_axis
        hi, lo = -np.inf, np.inf
        for g in plant.GetCollisionGeometriesForBody(body):
            X_body_g = inspector.GetPoseInFrame(g)
            R = X_body_g.rotation().inverse()
            offset = float(axis_part @ (X_body_g.translation() - X_part_grasp.translation()))
            shape = inspector.GetShape(g)
            hi = np.maximum(hi, offset + shape_support(shape, R @ axis_part))
            lo = np.minimum(lo, offset - shape_support(shape, R @ -axis_part))
        widths[instance] = float(hi - lo)
        grasps[instance] = tcp_in_part(X_part_grasp, widths[instance])
    tray = plant.GetBodyByName(TRAY, plant.GetModelInstanceByName(TRAY))
    return CellFrames(
        design, seats, homes, rows, grasps, widths, tray.EvalPoseInWorld(plant_context)
    )


def _finger_axis_in_tcp(plant: MultibodyPlant, plant_context) -> np.ndarray:
    """Unit direction the left finger opens along, in the tcp frame."""
    gripper = plant.GetModelInstanceByName(GRIPPER)
    R_W_base = plant.GetFrameByName("rg2_base", gripper).CalcPoseInWorld(plant_context).rotation()
    R_W_tcp = plant.GetFrameByName(TCP, gripper).CalcPoseInWorld(plant_context).rotation()
    axis = R_W_tcp.inverse() @ R_W_base @ np.asarray(RG2_OPENING_AXIS)
    return axis / np.linalg.norm(axis)
