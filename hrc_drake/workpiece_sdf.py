"""The SDF text of the cell's generated workpiece models — the base plate, the tray and the
parts — and the pocket/boss geometry they share.

The plate, the tray and the parts are generated together because that geometry locates a part in
a seat; `hrc_drake.cell_models.CellDesign` decides which models a spec and layout need and calls
these writers. They are apart from it because they only write text (no Drake): the design, the
plant and the checks of the built cell are `hrc_drake.cell_models`.

Geometry (metres):
- Every seat is a shallow pocket (depth `POCKET_DEPTH`) whose floor is its own collision box,
  named `<seat>_seat`, so contact tells which seat a part touches. Each part has a boss under it
  (one per covered seat, named `boss…`) that drops into the pocket with `POCKET_CLEARANCE` on
  each side.
- The boss is `SEAT_GAP` taller than the pocket is deep: a seated part rests on its boss(es) on
  the seat floor, its underside `SEAT_GAP` above the surrounding surface. So the part's weight is
  carried by the seat floor alone, and a seat frame sits where the part's underside (its body
  origin) is when seated: `X_W_part = X_W_seat` holds at rest.
- A boss's collision box reaches `BOSS_ROOT` up into its part (the same body: no contact
  between them); what shows is the boss under the part. A compliant box's pressure field rises
  from its faces to half its least dimension in, and past that its gradient turns and pulls a
  body further in. A part that falls out of the gripper (a lost grip) strikes at up to 1 m/s,
  10 mm in one 10 ms step. With the boss's box only its 4.5 mm height, an oval flange dropped
  turned across a pocket sank its boss between the pocket's rims and stayed wedged there, held
  by balanced contact forces of 0.7-1.3 kN that no grasp lifts: 9 of 24 drops at 5e6 Pa, 12 of
  24 at 1e7 Pa (benchmarks/bench_contact.py, section 5), and every lost grip the 4-slot cell
  did not recover at 1e7 Pa. Reaching up 8 mm, its field is 6.25 mm deep, its modulus scaled
  so that it presses as before (`BOSS_MODULUS_SCALE`), and the same drops wedge none. (Rims
  and floors reaching down through the plate also kept them from wedging, but would make the
  plate press softer: not kept.)
- Every collision geometry is compliant hydroelastic (its material is the scenario's
  `scene_graph_config`, applied by the station), the plate and the tray too, although they never
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

import math
from dataclasses import dataclass, replace

# Model instance names of the generated plate and tray (the table's is `cell_models.TABLE`; the
# parts are named by `CellDesign`).
PLATE = "base_plate"
TRAY = "tray"

POCKET_DEPTH = 0.004
SEAT_GAP = 0.0005
BOSS = (0.030, 0.020, POCKET_DEPTH + SEAT_GAP)  # x, y, height below the part's underside
POCKET_CLEARANCE = 0.0015
POCKET = (BOSS[0] + 2 * POCKET_CLEARANCE, BOSS[1] + 2 * POCKET_CLEARANCE)
FLOOR_SLACK = 0.001  # the slab under a pocket floor stays this far below it: only the floor touches
SEAT_THICKNESS = 0.003
# How far a boss's collision box reaches up into its part: below the least part thickness (the
# oval flange's and the bar's 10 mm) and below a host's pocket floors (12 mm).
BOSS_ROOT = 0.008
# A compliant box's pressure rises to its modulus half its least dimension in, so the deeper
# box alone would press 2.8 times softer per millimetre than the boss did, and a flange let
# go above a host's row then caught on the rim (F01 on S12 read misplaced, 3.1 mm off). Its
# modulus is the scenario's times this ratio of the depths: it presses as the 4.5 mm boss did,
# only its field turns deeper (the station applies it: hrc_drake.cell.station.build).
BOSS_MODULUS_SCALE = (BOSS[2] + BOSS_ROOT) / BOSS[2]
BOSS_NAME = "boss"  # a boss's collision name: "boss", or "boss_<i>" on a part with several


def is_boss(geometry_name: str) -> bool:
    """Whether a collision geometry (its SceneGraph name, `<model>::<name>`) is a part's boss."""
    return geometry_name.rsplit("::", 1)[-1].split("_")[0] == BOSS_NAME


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
BOSS_RGBA = "0.45 0.45 0.5 1"


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
    # size, dissipation, friction) are the scenario's `scene_graph_config`, which the station hands
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
        # The text names cell_models.py, whose CellDesign generates a cell: kept as it was, so
        # that the generated models stay byte-for-byte the same.
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
        name = f"{BOSS_NAME}_{i}" if len(bosses) > 1 else BOSS_NAME
        # The collision box reaches up into the part (the module docstring).
        root = Box(name, (BOSS[0], BOSS[1], bh + BOSS_ROOT), (x, 0, (BOSS_ROOT - bh) / 2))
        parts.append(_collision_box(root, compliant=True))
        parts.append(_visual_box(Box(name, (BOSS[0], BOSS[1], bh), (x, 0, -bh / 2)), BOSS_RGBA))
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
