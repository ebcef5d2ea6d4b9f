"""The cell's models for one assembly spec and layout: what the cell is made of (`CellDesign`),
adding it to a plant (`add_cell_models`) and checking a built plant against the spec
(`check_cell_models`).

The plate, the tray and the parts are generated, as SDF text, when the cell is built
(`hrc_drake/workpiece_sdf.py` writes them and holds the pocket/boss geometry they share): a new
assembly spec is a new cell, with nothing to regenerate or keep in step by hand. The UR3, the
gripper and the table are fixed model files under `models/`.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import LoadModelDirectivesFromString, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from hrc_drake.layout import CellLayout, layout_from
from hrc_drake.resources import package_uri
from hrc_drake.robot_models import add_robot, make_parser
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.workpiece_sdf import (
    BAR_WIDTH,
    GRASP_HEIGHT,
    HOST_END,
    HOST_THICKNESS,
    HOST_WIDTH,
    OVAL,
    PLATE,
    PLATE_END,
    POCKET,
    SEAT_GAP,
    TRAY,
    TRAY_SIZE,
    TrayHome,
    bar_sdf,
    host_sdf,
    oval_sdf,
    plate_sdf,
    slot_offsets,
    tray_layout,
    tray_sdf,
)

# Model instance name of the table (models/cell/table.sdf).
TABLE = "table"


class CellModelError(ValueError):
    """An assembly spec or layout the cell cannot be built for; the message names the fix."""


@dataclass(frozen=True)
class PartInstance:
    """One physical part: its model instance name, spec symbol, body name and shape.

    `shape` is ``oval``, ``host`` or ``bar`` for a generated model, ``file`` for a model file
    named in the layout's `part_models` (`model_file`).
    """

    name: str
    symbol: str
    body: str
    shape: str
    model_file: str | None = None


def _snake(text: str) -> str:
    out = "".join(c.lower() if c.isalnum() else "_" for c in text.strip())
    return "_".join(filter(None, out.split("_")))


@dataclass(frozen=True, eq=False)
class CellDesign:
    """What the cell is made of for one assembly spec and layout: the generated models, the part
    instances (one per part of the spec), and where the plate and the tray stand.

    Build it with `CellDesign.of(spec, layout)`; `add_cell_models` puts it in a plant.
    """

    spec: AssemblySpec
    layout: CellLayout
    parts: tuple[PartInstance, ...]

    @staticmethod
    def of(spec: AssemblySpec, layout: CellLayout | None = None) -> CellDesign:
        """The design for `spec`: the layout from `layout`, else the spec's `cell:` section."""
        try:
            layout = layout_from(spec.cell, layout)
        except ValueError as err:
            raise CellModelError(f"assembly spec {spec.source}: {err}") from err
        unknown = sorted(set(layout.part_models) - {p.symbol for p in spec.parts})
        if unknown:
            raise CellModelError(
                f"cell.part_models names {unknown[0]!r}, which is not a part of {spec.source}; "
                f"parts are {[p.symbol for p in spec.parts]}"
            )
        instances, bodies = [], set()
        for part in spec.parts:
            body = _snake(part.name) or part.symbol.lower()
            if body in bodies or body in (TABLE, PLATE, TRAY, UR3, GRIPPER):
                body = f"{body}_{part.symbol.lower()}"
            bodies.add(body)
            hosted = any(m.on == part.symbol for m in spec.mounts)
            shape = "host" if hosted else ("oval" if part.footprint == 1 else "bar")
            model_file = layout.part_models.get(part.symbol)
            if model_file is not None:
                shape = "file"
            for i in range(1, part.count + 1):
                name = body if part.count == 1 else f"{body}_{i}"
                instances.append(PartInstance(name, part.symbol, body, shape, model_file))
        return CellDesign(spec, layout, tuple(instances))

    @property
    def slots(self) -> int:
        """Base slots (plate seats)."""
        return self.spec.slots

    @property
    def instance_names(self) -> tuple[str, ...]:
        """Part instance names in spec order."""
        return tuple(p.name for p in self.parts)

    def instances_of(self, symbol: str) -> tuple[str, ...]:
        """The instances of a spec part symbol, in the order free ones are taken from the tray."""
        return tuple(p.name for p in self.parts if p.symbol == symbol)

    def instance(self, name: str) -> PartInstance:
        """The part instance called `name`; KeyError naming the instances if unknown."""
        for part in self.parts:
            if part.name == name:
                return part
        raise KeyError(f"no part instance {name!r}; the parts are {', '.join(self.instance_names)}")

    def symbol_of(self, name: str) -> str:
        """The spec symbol of a part instance."""
        return self.instance(name).symbol

    @property
    def host_tags(self) -> dict[str, str]:
        """Host instance -> the tag tokens of parts on it carry (``F01``: ``0``)."""
        return {
            p.name: self.spec.part(p.symbol).host_tag
            for p in self.parts
            if self.spec.part(p.symbol).is_host
        }

    def key(self) -> tuple:
        """A hashable identity of the cell (spec content, layout)."""
        return (self.spec.spec_hash, self.layout.key())

    @property
    def cell_hash(self) -> str:
        """A short hash of the cell's geometry: spec content, layout and generator constants."""
        constants = (POCKET, SEAT_GAP, OVAL, HOST_WIDTH, HOST_THICKNESS, GRASP_HEIGHT, TRAY_SIZE)
        text = json.dumps([repr(self.key()), repr(constants)])
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def part_sdf(self, part: PartInstance) -> str:
        """The generated SDF of a part instance (not for ``file`` parts)."""
        pitch = self.layout.slot_pitch
        footprint = self.spec.part(part.symbol).footprint
        if part.shape == "host":
            return host_sdf(part.name, part.body, footprint, pitch)
        if part.shape == "oval":
            return oval_sdf(part.name, part.body)
        if part.shape == "bar":
            return bar_sdf(part.name, part.body, footprint, pitch)
        raise CellModelError(f"part {part.name} comes from the file {part.model_file}")

    def plate_sdf(self) -> str:
        """The generated base plate."""
        return plate_sdf(self.slots, self.layout.slot_pitch)

    def tray(self) -> tuple[list[TrayHome], tuple[float, float, float]]:
        """Tray homes of every part and the tray's size."""
        pitch = self.layout.slot_pitch
        entries = []
        order = sorted(
            range(len(self.parts)),
            key=lambda i: -self.spec.part(self.parts[i].symbol).footprint,
        )
        for i in order:
            part = self.parts[i]
            footprint = self.spec.part(part.symbol).footprint
            bosses = tuple(slot_offsets(footprint, pitch))
            if part.shape == "host":
                length, width = pitch * (footprint - 1) + 2 * HOST_END, HOST_WIDTH
            elif part.shape == "bar":
                length, width = pitch * (footprint - 1) + OVAL[0], BAR_WIDTH
            else:
                length, width = OVAL[0], OVAL[1]
            entries.append((part.name, length, width, bosses))
        return tray_layout(entries)

    def tray_sdf(self) -> str:
        """The generated tray."""
        homes, size = self.tray()
        return tray_sdf(homes, size)

    def X_W_plate(self) -> RigidTransform:
        """The plate's body frame in world."""
        return _pose(self.layout.plate_position, self.layout.plate_yaw_deg)

    def X_W_tray(self) -> RigidTransform:
        """The tray's body frame in world (see `CellLayout.tray_position`)."""
        layout = self.layout
        X_W_plate = self.X_W_plate()
        yaw = layout.plate_yaw_deg + layout.tray_yaw_deg
        if layout.tray_position is not None:
            return _pose(layout.tray_position, yaw)
        plate_length = layout.slot_pitch * (self.slots - 1) + 2 * PLATE_END
        _homes, (_length, tray_width, _height) = self.tray()
        # Beside slot 1 (the plate's -x end), toward the robot (the plate's +y is world -x at
        # the default yaw of 90°).
        x = -(plate_length / 2 + layout.tray_gap + tray_width / 2)
        p_W = X_W_plate @ np.array([x, layout.tray_offset, 0.0])
        return _pose(p_W, yaw)


TABLE_POSITION = (0.25, 0.0, 0.0)  # the table's top face, at its centre (models/cell/table.sdf)
TABLE_HALF = 0.5  # m: the table is 1 m x 1 m (models/cell/table.sdf)


def _pose(position, yaw_deg: float) -> RigidTransform:
    return RigidTransform(RollPitchYaw(0.0, 0.0, math.radians(yaw_deg)), np.asarray(position))


def _resolve_model_file(parser, model_file: str) -> str:
    if model_file.startswith("package://"):
        return parser.package_map().ResolveUrl(model_file)
    return str(Path(model_file).expanduser().resolve())


def add_cell_models(
    plant: MultibodyPlant, design: CellDesign, include_robot: bool = True
) -> dict[str, ModelInstanceIndex]:
    """Add the cell to `plant`: the UR3 and gripper (models/cell/robot.dmd.yaml) if asked, the
    table, and the design's plate, tray and parts (generated, or from `part_models` files).

    The plate and the tray are welded where the layout puts them; parts are free bodies (their
    poses are set by the caller). Returns model instance name -> index. CellModelError names a
    part model file that is missing.
    """
    parser = make_parser(plant)
    instances: dict[str, ModelInstanceIndex] = {}
    if include_robot:
        instances[UR3], instances[GRIPPER] = add_robot(plant)
    (table,) = parser.AddModels(url=package_uri("cell/table.sdf"))
    plant.WeldFrames(
        plant.world_frame(),
        plant.GetBodyByName(TABLE, table).body_frame(),
        RigidTransform(np.asarray(TABLE_POSITION)),
    )
    instances[TABLE] = table
    for name, text, X_W in (
        (PLATE, design.plate_sdf(), design.X_W_plate()),
        (TRAY, design.tray_sdf(), design.X_W_tray()),
    ):
        (model,) = parser.AddModelsFromString(text, "sdf")
        plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(name, model).body_frame(), X_W)
        instances[name] = model
    for part in design.parts:
        if part.shape != "file":
            (model,) = parser.AddModelsFromString(design.part_sdf(part), "sdf")
        else:
            path = _resolve_model_file(parser, part.model_file)
            if not Path(path).is_file():
                raise CellModelError(
                    f"part {part.symbol}: its model file {part.model_file} does not exist; fix "
                    "cell.part_models in the spec or scenario (or drop it to use a generated one)"
                )
            directives = LoadModelDirectivesFromString(
                json.dumps(
                    {"directives": [{"add_model": {"name": part.name, "file": "file://" + path}}]}
                )
            )
            (info,) = ProcessModelDirectives(directives, plant, parser)
            model = info.model_instance
        instances[part.name] = model
    return instances


def _collision_names(plant: MultibodyPlant, inspector, body) -> list[str]:
    return [inspector.GetName(g).split("::")[-1] for g in plant.GetCollisionGeometriesForBody(body)]


def check_cell_models(plant: MultibodyPlant, scene_graph, design: CellDesign) -> None:
    """Check a finalized plant's cell models against the spec, before anything is simulated.

    Spec slots = plate seats (`slot_k` frames with `slot_k_seat` floors), one model instance per
    part, each part's footprint = its bosses, every host row (`row_j` + `row_j_seat`), a `grasp`
    frame on every part and a tray home for every part. CellModelError names the part or slot
    and what to change.
    """
    inspector = scene_graph.model_inspector()
    spec = design.spec
    _check_plate(plant, inspector, spec)
    tray = _instance(plant, TRAY, "the tray")
    counts: dict[str, int] = {}
    for part in design.parts:
        _check_part(plant, inspector, spec, part, tray)
        counts[part.symbol] = counts.get(part.symbol, 0) + 1
    for spec_part in spec.parts:
        if counts.get(spec_part.symbol, 0) != spec_part.count:
            raise CellModelError(
                f"part {spec_part.symbol}: the spec counts {spec_part.count}, the cell has "
                f"{counts.get(spec_part.symbol, 0)} model instances"
            )


def _instance(plant: MultibodyPlant, name: str, what: str) -> ModelInstanceIndex:
    """The model instance `name`; CellModelError saying what is missing (`what`)."""
    if not plant.HasModelInstanceNamed(name):
        raise CellModelError(f"the cell has no model instance {name!r} ({what})")
    return plant.GetModelInstanceByName(name)


def _check_plate(plant: MultibodyPlant, inspector, spec: AssemblySpec) -> None:
    """The plate has one seat frame per base slot, each with its floor geometry."""
    plate = _instance(plant, PLATE, "the base plate")
    plate_body = plant.GetBodyByName(PLATE, plate)
    names = set(_collision_names(plant, inspector, plate_body))
    seats = 0
    while plant.HasFrameNamed(f"slot_{seats + 1}", plate):
        seats += 1
    if seats != spec.slots:
        raise CellModelError(
            f"{spec.source}: the spec's base has {spec.slots} slots but the plate has {seats} "
            "seat frames; the plate comes from base.slots: rebuild the cell from this spec"
        )
    for k in range(1, seats + 1):
        if f"slot_{k}_seat" not in names:
            raise CellModelError(f"the plate's slot {k} has no floor geometry slot_{k}_seat")


def _check_part(
    plant: MultibodyPlant,
    inspector,
    spec: AssemblySpec,
    part: PartInstance,
    tray: ModelInstanceIndex,
) -> None:
    """One part instance: one rigid body, a boss per slot of its footprint, a `grasp` frame,
    a row per slot it covers if it is a host, and its home in the tray."""
    model = _instance(plant, part.name, f"part {part.symbol} of the spec")
    bodies = plant.GetBodyIndices(model)
    if len(bodies) != 1:
        raise CellModelError(
            f"part model {part.name} has {len(bodies)} bodies; a part is one rigid body"
        )
    body = plant.get_body(bodies[0])
    geometry = _collision_names(plant, inspector, body)
    spec_part = spec.part(part.symbol)
    bosses = sum(1 for n in geometry if n.startswith("boss"))
    if bosses != spec_part.footprint:
        raise CellModelError(
            f"part {part.symbol} ({part.name}) has {bosses} bosses but its footprint in "
            f"{spec.source} is {spec_part.footprint}; give its model one `boss…` collision "
            "geometry per slot it covers, or fix parts."
            f"{part.symbol}.footprint"
        )
    if not plant.HasFrameNamed("grasp", model):
        raise CellModelError(
            f"part {part.symbol} ({part.name}) has no `grasp` frame: add one where the "
            "gripper's tcp holds it (docs/conventions.md)"
        )
    if spec_part.is_host:
        for j in range(1, spec_part.footprint + 1):
            if not plant.HasFrameNamed(f"row_{j}", model) or f"row_{j}_seat" not in geometry:
                raise CellModelError(
                    f"host part {part.symbol} ({part.name}) has no row {j} (frame row_{j} "
                    f"and floor geometry row_{j}_seat); a host needs one row per slot it "
                    "covers"
                )
    if not plant.HasFrameNamed(f"home_{part.name}", tray):
        raise CellModelError(f"the tray has no home frame home_{part.name} for {part.name}")
