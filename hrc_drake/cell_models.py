"""The cell's workpiece models, generated from an assembly spec and a cell layout.

The plate, the tray and the parts share the pocket/boss geometry that locates a part in a seat,
so they are generated together, as SDF text, when the cell is built: a new assembly spec is a new
cell, with nothing to regenerate or keep in step by hand. The UR3, the gripper and the table are
fixed model files under `models/`.

Geometry (metres):
- Every seat is a shallow pocket (depth `POCKET_DEPTH`) whose floor is its own collision box,
  named `<seat>_seat`, so contact tells which seat a part touches. Each part has a boss under it
  (one per covered seat, named `boss…`) that drops into the pocket with `POCKET_CLEARANCE` on
  each side.
- The boss is `SEAT_GAP` taller than the pocket is deep: a seated part rests on its boss(es) on
  the seat floor, its underside `SEAT_GAP` above the surrounding surface. So the part's weight is
  carried by the seat floor alone, and a seat frame sits where the part's underside (its body
  origin) is when seated: `X_W_part = X_W_seat` holds at rest.
- Every collision geometry is compliant hydroelastic (its material is the scenario's
  `physics.contact`, applied by the station), the plate and the tray too, although they never
  move: rigid ones would be cheaper, but a part let go a few mm above a rigid seat moves more
  than the hydroelastic margin in one 5 ms step, falls through the rigid floor's surface before
  the contact pushes back, and is thrown out of its pocket (a 3 mm drop: 9 of 12 settling runs
  failed; compliant-on-compliant rests in all of them; benchmarks/reports/contact.md).
- Part shapes follow the part's role in the spec: a host part (others mount on it) is a plate
  with one pocketed row per base slot it covers (the square flange: 2 rows); a part that covers
  one slot is an oval flange; a part over several slots and hosting nothing is a bar with one
  boss per slot. The flange case's plate, flanges and tray are those of the paper's cell.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import LoadModelDirectivesFromString, ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from hrc_drake.layout import CellLayout, layout_from
from hrc_drake.resources import package_uri
from hrc_drake.robot_models import GRIPPER, UR3, add_robot, make_parser
from hrc_drake.tasks.spec import AssemblySpec

# Model instance names of the cell's fixed models (the parts are named by `CellDesign`).
PLATE = "base_plate"
TRAY = "tray"
TABLE = "table"

POCKET_DEPTH = 0.004
SEAT_GAP = 0.0005
BOSS = (0.030, 0.020, POCKET_DEPTH + SEAT_GAP)  # x, y, height below the part's underside
POCKET_CLEARANCE = 0.0015
POCKET = (BOSS[0] + 2 * POCKET_CLEARANCE, BOSS[1] + 2 * POCKET_CLEARANCE)
FLOOR_SLACK = 0.001  # the slab under a pocket floor stays this far below it: only the floor touches
SEAT_THICKNESS = 0.003

PLATE_WIDTH, PLATE_THICKNESS = 0.120, 0.015
PLATE_END = 0.070  # plate beyond the first and last slot centres (0.300 m long for 3 slots)
OVAL = (0.065, 0.045, 0.010)
HOST_WIDTH, HOST_THICKNESS = 0.090, 0.016
HOST_END = 0.035  # host plate beyond its outer rows (the square: 0.150 m for 2 rows)
BAR_WIDTH, BAR_THICKNESS = 0.045, 0.010
TRAY_SIZE = (0.290, 0.170, 0.012)  # the least tray; longer when more parts need room
TRAY_EDGE_ROOM = 0.030  # from the tray's end to the first part's edge
TRAY_COLUMN_GAP = 0.0625  # between the edges of parts in neighbouring columns: two fingers' room
TRAY_ROW_GAP = 0.015  # between the ends of parts lying end to end in one column

ALUMINIUM_DENSITY = 2700.0

# Height of the gripper's tcp above a part's underside when it holds the part. The RG2 pads reach
# 12.5 mm either side of the tcp (models/rg2/rg2.sdf), so this keeps their lower edge 1.5 mm above
# the underside, 2 mm above the surface a seated part sits on.
GRASP_HEIGHT = 0.014


@dataclass(frozen=True)
class Box:
    name: str
    size: tuple[float, float, float]
    centre: tuple[float, float, float]


def _f(x: float) -> str:
    text = f"{x:.9f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _v(values) -> str:
    return " ".join(_f(v) for v in values)


def _proximity(compliant: bool) -> str:
    # A compliant geometry states nothing: compliance and the whole material (modulus, mesh
    # size, dissipation, friction) are the scenario's `physics.contact`, which the station hands
    # to Drake as SceneGraphConfig defaults. Only a rigid geometry says so.
    if compliant:
        return ""
    return (
        "\n        <drake:proximity_properties>\n"
        "          <drake:rigid_hydroelastic/>\n"
        "        </drake:proximity_properties>"
    )


def _collision_box(box: Box, compliant: bool) -> str:
    return (
        f'      <collision name="{box.name}">\n'
        f"        <pose>{_v(box.centre)} 0 0 0</pose>\n"
        f"        <geometry><box><size>{_v(box.size)}</size></box></geometry>"
        f"{_proximity(compliant)}\n"
        f"      </collision>"
    )


def _visual(name: str, pose: tuple, geometry: str, rgba: str) -> str:
    return (
        f'      <visual name="{name}">\n'
        f"        <pose>{_v(pose)}</pose>\n"
        f"        <geometry>{geometry}</geometry>\n"
        f"        <material><diffuse>{rgba}</diffuse></material>\n"
        f"      </visual>"
    )


def _visual_box(box: Box, rgba: str) -> str:
    return _visual(
        box.name + "_visual",
        (*box.centre, 0, 0, 0),
        f"<box><size>{_v(box.size)}</size></box>",
        rgba,
    )


def _frame(name: str, body: str, pose: tuple) -> str:
    return (
        f'    <frame name="{name}" attached_to="{body}">\n'
        f"      <pose>{_v(pose)}</pose>\n    </frame>"
    )


def _inertial(mass: float, size: tuple[float, float, float], com_z: float) -> str:
    x, y, z = size
    ixx = mass * (y * y + z * z) / 12
    iyy = mass * (x * x + z * z) / 12
    izz = mass * (x * x + y * y) / 12
    return (
        "      <inertial>\n"
        f"        <pose>0 0 {_f(com_z)} 0 0 0</pose>\n"
        f"        <mass>{_f(mass)}</mass>\n"
        f"        <inertia><ixx>{ixx:.4e}</ixx><iyy>{iyy:.4e}</iyy><izz>{izz:.4e}</izz>"
        "<ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>\n"
        "      </inertial>"
    )


def pocketed_slab(
    length: float, width: float, top: float, bottom: float, seats: dict[str, float]
) -> list[Box]:
    """Boxes of a slab from z=bottom to z=top with pockets centred at x=seats[name], y=0.

    The top surface is split into two side strips and cross bars between the pockets; each
    pocket floor is its own box `<name>_seat`; the slab under them stays below the floor.
    """
    a, b = POCKET
    floor = top - POCKET_DEPTH
    slab_top = floor - FLOOR_SLACK
    boxes = [Box("slab", (length, width, slab_top - bottom), (0, 0, (slab_top + bottom) / 2))]
    wall_h = top - slab_top
    side_w = (width - b) / 2
    for sign, tag in ((1, "far"), (-1, "near")):
        boxes.append(
            Box(
                f"rim_{tag}",
                (length, side_w, wall_h),
                (0, sign * (b + side_w) / 2, top - wall_h / 2),
            )
        )
    edges = [-length / 2]
    for x in sorted(seats.values()):
        edges += [x - a / 2, x + a / 2]
    edges.append(length / 2)
    for i in range(0, len(edges), 2):
        x0, x1 = edges[i], edges[i + 1]
        boxes.append(
            Box(f"bar_{i // 2}", (x1 - x0, b, wall_h), ((x0 + x1) / 2, 0, top - wall_h / 2))
        )
    for name, x in seats.items():
        boxes.append(
            Box(f"{name}_seat", (a, b, SEAT_THICKNESS), (x, 0, floor - SEAT_THICKNESS / 2))
        )
    return boxes


def _model(name: str, body: str, static_note: str, link: str, frames: list[str]) -> str:
    return (
        '<?xml version="1.0"?>\n'
        "<!-- Generated by hrc_drake/cell_models.py from an assembly spec and a layout.\n"
        f"     {static_note} -->\n"
        '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">\n'
        f'  <model name="{name}">\n'
        f'    <link name="{body}">\n'
        f"{link}\n"
        "    </link>\n" + "".join(f + "\n" for f in frames) + "  </model>\n</sdf>\n"
    )


def slot_offsets(count: int, pitch: float) -> list[float]:
    """Positions along a row of `count` seats `pitch` apart, centred on 0 (seat 1 at -x)."""
    return [(k - (count + 1) / 2) * pitch for k in range(1, count + 1)]


def plate_sdf(slots: int, pitch: float) -> str:
    """The base plate: `slots` pocketed seats `slot_k`, `pitch` apart, along its +x."""
    length = pitch * (slots - 1) + 2 * PLATE_END
    size = (length, PLATE_WIDTH, PLATE_THICKNESS)
    seats = {f"slot_{k}": x for k, x in enumerate(slot_offsets(slots, pitch), start=1)}
    boxes = pocketed_slab(length, PLATE_WIDTH, PLATE_THICKNESS, 0.0, seats)
    parts = [_collision_box(b, compliant=True) for b in boxes]
    parts += [
        _visual_box(b, "0.55 0.57 0.6 1" if "seat" not in b.name else "0.3 0.32 0.35 1")
        for b in boxes
    ]
    # Bolt holes: two dark dots beside each pocket, the "rows of holes" of the paper.
    for k, x in enumerate(seats.values(), start=1):
        for sign in (1, -1):
            parts.append(
                _visual(
                    f"slot_{k}_hole_{'far' if sign > 0 else 'near'}",
                    (x, sign * 0.037, PLATE_THICKNESS + 0.0001, 0, 0, 0),
                    "<cylinder><radius>0.004</radius><length>0.0002</length></cylinder>",
                    "0.1 0.1 0.1 1",
                )
            )
    mass = ALUMINIUM_DENSITY * length * PLATE_WIDTH * PLATE_THICKNESS
    link = _inertial(mass, size, PLATE_THICKNESS / 2) + "\n" + "\n".join(parts)
    frames = [
        _frame(n, PLATE, (x, 0, PLATE_THICKNESS + SEAT_GAP, 0, 0, 0)) for n, x in seats.items()
    ]
    return _model(
        PLATE,
        PLATE,
        f"Body frame at the plate's underside centre; +x from slot 1 to slot {slots}.",
        link,
        frames,
    )


def _bosses(bosses: list[float]) -> list[str]:
    parts = []
    bh = BOSS[2]
    for i, x in enumerate(bosses, start=1):
        boss = Box(
            f"boss_{i}" if len(bosses) > 1 else "boss", (BOSS[0], BOSS[1], bh), (x, 0, -bh / 2)
        )
        parts.append(_collision_box(boss, compliant=True))
        parts.append(_visual_box(boss, "0.45 0.45 0.5 1"))
    return parts


def _grasp_pose() -> tuple:
    # tcp +z points down into the part (approach direction); the fingers close across the part's
    # width (its y axis): tcp x along the part's x, tcp y along the part's -y.
    return (0, 0, GRASP_HEIGHT, math.pi, 0, 0)


def oval_sdf(model: str, body: str) -> str:
    """An oval flange over one seat (the paper's F): a slotted oval plate with one boss."""
    length, width, thick = OVAL
    r = width / 2
    core = length - width
    parts = _bosses([0.0])
    box = Box("body", (core, width, thick), (0, 0, thick / 2))
    parts.append(_collision_box(box, compliant=True))
    rgba = "0.85 0.55 0.15 1"
    parts.append(_visual_box(box, rgba))
    for sign, tag in ((1, "end_pos"), (-1, "end_neg")):
        pose = (sign * core / 2, 0, thick / 2, 0, 0, 0)
        cyl = f"<cylinder><radius>{_f(r)}</radius><length>{_f(thick)}</length></cylinder>"
        parts.append(
            f'      <collision name="{tag}">\n        <pose>{_v(pose)}</pose>\n'
            f"        <geometry>{cyl}</geometry>{_proximity(True)}\n      </collision>"
        )
        parts.append(_visual(tag + "_visual", pose, cyl, rgba))
        parts.append(
            _visual(
                f"hole_{tag}",
                (sign * (core / 2 + 0.008), 0, thick + 0.0001, 0, 0, 0),
                "<cylinder><radius>0.0035</radius><length>0.0002</length></cylinder>",
                "0.1 0.1 0.1 1",
            )
        )
    volume = core * width * thick + math.pi * r * r * thick
    link = _inertial(ALUMINIUM_DENSITY * volume, OVAL, thick / 2) + "\n" + "\n".join(parts)
    return _model(
        model,
        body,
        "Body frame at the flange's underside centre (the boss protrudes below it).",
        link,
        [_frame("grasp", body, _grasp_pose())],
    )


def host_sdf(model: str, body: str, rows: int, pitch: float) -> str:
    """A part others mount on (the paper's square flange S): one boss and one pocketed row
    `row_j` per base slot it covers, `row_1` over the lowest-numbered slot (at -x)."""
    length = pitch * (rows - 1) + 2 * HOST_END
    size = (length, HOST_WIDTH, HOST_THICKNESS)
    seats = {f"row_{j}": x for j, x in enumerate(slot_offsets(rows, pitch), start=1)}
    parts = _bosses(list(seats.values()))
    boxes = pocketed_slab(length, HOST_WIDTH, HOST_THICKNESS, 0.0, seats)
    rgba = "0.2 0.45 0.75 1"
    parts += [_collision_box(b, compliant=True) for b in boxes]
    parts += [_visual_box(b, rgba if "seat" not in b.name else "0.15 0.3 0.5 1") for b in boxes]
    for sx in (1, -1):
        for sy in (1, -1):
            parts.append(
                _visual(
                    f"hole_{'p' if sx > 0 else 'n'}{'p' if sy > 0 else 'n'}",
                    (sx * (length / 2 - 0.011), sy * 0.035, HOST_THICKNESS + 0.0001, 0, 0, 0),
                    "<cylinder><radius>0.004</radius><length>0.0002</length></cylinder>",
                    "0.1 0.1 0.1 1",
                )
            )
    volume = length * HOST_WIDTH * HOST_THICKNESS - rows * POCKET[0] * POCKET[1] * POCKET_DEPTH
    link = _inertial(ALUMINIUM_DENSITY * volume, size, HOST_THICKNESS / 2) + "\n" + "\n".join(parts)
    frames = [_frame(n, body, (x, 0, HOST_THICKNESS + SEAT_GAP, 0, 0, 0)) for n, x in seats.items()]
    frames.append(_frame("grasp", body, _grasp_pose()))
    return _model(
        model,
        body,
        f"Body frame at the part's underside centre, between its {rows} bosses; row_1 at -x.",
        link,
        frames,
    )


def bar_sdf(model: str, body: str, span: int, pitch: float) -> str:
    """A part over `span` slots that hosts nothing: a bar with one boss per slot."""
    length = pitch * (span - 1) + OVAL[0]
    size = (length, BAR_WIDTH, BAR_THICKNESS)
    parts = _bosses(slot_offsets(span, pitch))
    box = Box("body", size, (0, 0, BAR_THICKNESS / 2))
    parts.append(_collision_box(box, compliant=True))
    parts.append(_visual_box(box, "0.55 0.35 0.7 1"))
    mass = ALUMINIUM_DENSITY * length * BAR_WIDTH * BAR_THICKNESS
    link = _inertial(mass, size, BAR_THICKNESS / 2) + "\n" + "\n".join(parts)
    return _model(
        model,
        body,
        f"Body frame at the bar's underside centre, between its {span} bosses.",
        link,
        [_frame("grasp", body, _grasp_pose())],
    )


@dataclass(frozen=True)
class TrayHome:
    """Where one part rests in the tray: tray-frame position, yaw, and its bosses' x offsets."""

    instance: str
    x: float
    y: float
    yaw: float
    bosses: tuple[float, ...]


TRAY_RIM = 0.006


def tray_layout(
    parts: list[tuple[str, float, float, tuple[float, ...]]],
) -> tuple[list[TrayHome], tuple[float, float, float]]:
    """Pack parts (instance, length, width, boss offsets) into columns across the tray.

    Each part lies turned by 90° (its length along the tray's y), so the fingers, which close
    across a part's width, close along the tray's x: neighbouring columns keep two fingers' room
    between them. Parts of one width lie end to end in a column while they fit the tray's width.
    Returns the homes and the tray's size (the least tray, longer or wider when parts need it).
    """
    tray_width = max(TRAY_SIZE[1], max(p[1] for p in parts) + 0.02)
    capacity = tray_width - 0.02
    columns: list[list[tuple[str, float, float, tuple[float, ...]]]] = []
    for part in parts:
        if columns and columns[-1][0][2] == part[2]:
            column = columns[-1]
            used = sum(p[1] for p in column) + TRAY_ROW_GAP * len(column)
            if used + part[1] <= capacity + 1e-9:
                column.append(part)
                continue
        columns.append([part])
    homes = []
    x = 0.0
    for i, column in enumerate(columns):
        width = max(p[2] for p in column)
        x += (TRAY_EDGE_ROOM if i == 0 else TRAY_COLUMN_GAP) + width / 2
        span = sum(p[1] for p in column) + TRAY_ROW_GAP * (len(column) - 1)
        y = -span / 2
        for name, length, _width, bosses in column:
            homes.append(TrayHome(name, x, y + length / 2, math.pi / 2, bosses))
            y += length + TRAY_ROW_GAP
        x += width / 2
    tray_length = max(TRAY_SIZE[0], x + TRAY_EDGE_ROOM)
    homes = [replace(h, x=h.x - tray_length / 2) for h in homes]
    return homes, (tray_length, tray_width, TRAY_SIZE[2])


def tray_sdf(homes: list[TrayHome], size: tuple[float, float, float]) -> str:
    """The tray: a slab with a rimmed pocket for every boss of every part, and `home_<part>`
    frames where each part rests."""
    length, width, thick = size
    a, b = POCKET
    boxes = [Box("top", (length, width, thick), (0, 0, thick / 2))]
    frames = []
    for home in homes:
        c, s = math.cos(home.yaw), math.sin(home.yaw)
        for i, dx in enumerate(home.bosses, start=1):
            px, py = home.x + c * dx, home.y + s * dx
            # Pocket axes in the tray frame (yaw is a multiple of 90°).
            pa, pb = (a, b) if abs(c) > 0.5 else (b, a)
            tag = f"{home.instance}_{i}"
            rim_h = POCKET_DEPTH
            rz = thick + rim_h / 2  # rims stand on the tray top, which is the pocket floor
            boxes += [
                Box(
                    f"{tag}_rim_xp",
                    (TRAY_RIM, pb + 2 * TRAY_RIM, rim_h),
                    (px + (pa + TRAY_RIM) / 2, py, rz),
                ),
                Box(
                    f"{tag}_rim_xn",
                    (TRAY_RIM, pb + 2 * TRAY_RIM, rim_h),
                    (px - (pa + TRAY_RIM) / 2, py, rz),
                ),
                Box(f"{tag}_rim_yp", (pa, TRAY_RIM, rim_h), (px, py + (pb + TRAY_RIM) / 2, rz)),
                Box(f"{tag}_rim_yn", (pa, TRAY_RIM, rim_h), (px, py - (pb + TRAY_RIM) / 2, rz)),
            ]
        frames.append(
            _frame(f"home_{home.instance}", TRAY, (home.x, home.y, thick + BOSS[2], 0, 0, home.yaw))
        )
    parts = [_collision_box(bx, compliant=True) for bx in boxes]
    parts += [
        _visual_box(bx, "0.25 0.6 0.35 1" if bx.name == "top" else "0.2 0.45 0.28 1")
        for bx in boxes
    ]
    link = _inertial(2.0, size, thick / 2) + "\n" + "\n".join(parts)
    return _model(
        TRAY,
        TRAY,
        "Body frame at the tray's underside centre; a part's boss rests on the tray top.",
        link,
        frames,
    )


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


TABLE_POSITION = (0.25, 0.0, 0.0)


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

    def instance(name: str, what: str):
        if not plant.HasModelInstanceNamed(name):
            raise CellModelError(f"the cell has no model instance {name!r} ({what})")
        return plant.GetModelInstanceByName(name)

    plate = instance(PLATE, "the base plate")
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
    tray = instance(TRAY, "the tray")
    counts: dict[str, int] = {}
    for part in design.parts:
        model = instance(part.name, f"part {part.symbol} of the spec")
        counts[part.symbol] = counts.get(part.symbol, 0) + 1
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
    for spec_part in spec.parts:
        if counts.get(spec_part.symbol, 0) != spec_part.count:
            raise CellModelError(
                f"part {spec_part.symbol}: the spec counts {spec_part.count}, the cell has "
                f"{counts.get(spec_part.symbol, 0)} model instances"
            )
