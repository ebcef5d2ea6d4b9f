"""Write the workpiece models of the cell (`models/cell/*.sdf`) from one table of dimensions.

The plate, the tray and the flanges share the pocket/boss geometry that locates a part in a seat,
so they are generated together: change a dimension here and run

    python tools/make_cell_models.py

The SDF files are committed; nothing is generated at run time.

Geometry (metres):
- Every seat is a shallow pocket (depth `POCKET_DEPTH`) whose floor is its own collision box,
  named `<seat>_seat`, so contact tells which seat a part touches. Each part has a boss under it
  (one per covered seat) that drops into the pocket with `POCKET_CLEARANCE` on each side.
- The boss is `SEAT_GAP` taller than the pocket is deep: a seated part rests on its boss(es) on
  the seat floor, its underside `SEAT_GAP` above the surrounding surface. So the part's weight is
  carried by the seat floor alone, and a seat frame sits where the part's underside (its body
  origin) is when seated: `X_W_part = X_W_seat` holds at rest.
- Every collision geometry is compliant hydroelastic (`HYDRO_MODULUS`). A rigid tray was tried
  first: a 67 g oval flange resting on it (compliant box on rigid box) was thrown out of its
  pocket within 0.1 s at a 5 ms step, while compliant-on-compliant rests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

MODELS = Path(__file__).resolve().parent.parent / "models" / "cell"

POCKET_DEPTH = 0.004
SEAT_GAP = 0.0005
BOSS = (0.030, 0.020, POCKET_DEPTH + SEAT_GAP)  # x, y, height below the part's underside
POCKET_CLEARANCE = 0.0015
POCKET = (BOSS[0] + 2 * POCKET_CLEARANCE, BOSS[1] + 2 * POCKET_CLEARANCE)
FLOOR_SLACK = 0.001  # the slab under a pocket floor stays this far below it: only the floor touches
SEAT_THICKNESS = 0.003

SLOT_PITCH = 0.080
PLATE = (0.300, 0.120, 0.015)
OVAL = (0.065, 0.045, 0.010)
SQUARE = (0.150, 0.090, 0.016)
TRAY = (0.290, 0.170, 0.012)
TABLE = (1.000, 1.000, 0.040)

HYDRO_MODULUS = 2.0e7
RESOLUTION_HINT = 0.01
DISSIPATION = 10.0
MU_STATIC, MU_DYNAMIC = 0.6, 0.5
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


def _proximity(compliant: bool, hint: bool = False) -> str:
    lines = ["        <drake:proximity_properties>"]
    if compliant:
        lines += [
            "          <drake:compliant_hydroelastic/>",
            f"          <drake:hydroelastic_modulus>{HYDRO_MODULUS:g}</drake:hydroelastic_modulus>",
        ]
        if hint:
            hint_tag = "drake:mesh_resolution_hint"
            lines.append(f"          <{hint_tag}>{RESOLUTION_HINT}</{hint_tag}>")
    else:
        lines.append("          <drake:rigid_hydroelastic/>")
    lines += [
        f"          <drake:hunt_crossley_dissipation>{DISSIPATION}"
        "</drake:hunt_crossley_dissipation>",
        f"          <drake:mu_static>{MU_STATIC}</drake:mu_static>",
        f"          <drake:mu_dynamic>{MU_DYNAMIC}</drake:mu_dynamic>",
        "        </drake:proximity_properties>",
    ]
    return "\n".join(lines)


def _collision_box(box: Box, compliant: bool) -> str:
    return (
        f'      <collision name="{box.name}">\n'
        f"        <pose>{_v(box.centre)} 0 0 0</pose>\n"
        f"        <geometry><box><size>{_v(box.size)}</size></box></geometry>\n"
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
        "<!-- Generated by tools/make_cell_models.py; edit that file, not this one.\n"
        f"     {static_note} -->\n"
        '<sdf version="1.9" xmlns:drake="http://drake.mit.edu">\n'
        f'  <model name="{name}">\n'
        f'    <link name="{body}">\n'
        f"{link}\n"
        "    </link>\n" + "".join(f + "\n" for f in frames) + "  </model>\n</sdf>\n"
    )


def plate_sdf() -> str:
    length, width, thick = PLATE
    seats = {f"slot_{k}": (k - 2) * SLOT_PITCH for k in (1, 2, 3)}
    boxes = pocketed_slab(length, width, thick, 0.0, seats)
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
                    (x, sign * 0.037, thick + 0.0001, 0, 0, 0),
                    "<cylinder><radius>0.004</radius><length>0.0002</length></cylinder>",
                    "0.1 0.1 0.1 1",
                )
            )
    mass = ALUMINIUM_DENSITY * length * width * thick
    link = _inertial(mass, PLATE, thick / 2) + "\n" + "\n".join(parts)
    frames = [_frame(n, "base_plate", (x, 0, thick + SEAT_GAP, 0, 0, 0)) for n, x in seats.items()]
    return _model(
        "base_plate",
        "base_plate",
        "Body frame at the plate's underside centre; +x from slot 1 to slot 3.",
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


def oval_sdf() -> str:
    length, width, thick = OVAL
    r = width / 2
    core = length - width
    parts = _bosses([0.0])
    body = Box("body", (core, width, thick), (0, 0, thick / 2))
    parts.append(_collision_box(body, compliant=True))
    rgba = "0.85 0.55 0.15 1"
    parts.append(_visual_box(body, rgba))
    for sign, tag in ((1, "end_pos"), (-1, "end_neg")):
        pose = (sign * core / 2, 0, thick / 2, 0, 0, 0)
        cyl = f"<cylinder><radius>{_f(r)}</radius><length>{_f(thick)}</length></cylinder>"
        parts.append(
            f'      <collision name="{tag}">\n        <pose>{_v(pose)}</pose>\n'
            f"        <geometry>{cyl}</geometry>\n{_proximity(True, hint=True)}\n      </collision>"
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
    frames = [_frame("grasp", "oval_flange", _grasp_pose())]
    return _model(
        "oval_flange",
        "oval_flange",
        "Body frame at the flange's underside centre (the boss protrudes below it).",
        link,
        frames,
    )


def _grasp_pose() -> tuple:
    # tcp +z points down into the part (approach direction); the fingers close across the part's
    # width (its y axis): tcp x along the part's x, tcp y along the part's -y.
    return (0, 0, GRASP_HEIGHT, math.pi, 0, 0)


def square_sdf() -> str:
    length, width, thick = SQUARE
    rows = {"row_1": -SLOT_PITCH / 2, "row_2": SLOT_PITCH / 2}
    parts = _bosses(list(rows.values()))
    boxes = pocketed_slab(length, width, thick, 0.0, rows)
    rgba = "0.2 0.45 0.75 1"
    parts += [_collision_box(b, compliant=True) for b in boxes]
    parts += [_visual_box(b, rgba if "seat" not in b.name else "0.15 0.3 0.5 1") for b in boxes]
    for sx in (1, -1):
        for sy in (1, -1):
            parts.append(
                _visual(
                    f"hole_{'p' if sx > 0 else 'n'}{'p' if sy > 0 else 'n'}",
                    (sx * 0.064, sy * 0.035, thick + 0.0001, 0, 0, 0),
                    "<cylinder><radius>0.004</radius><length>0.0002</length></cylinder>",
                    "0.1 0.1 0.1 1",
                )
            )
    volume = length * width * thick - 2 * POCKET[0] * POCKET[1] * POCKET_DEPTH
    link = _inertial(ALUMINIUM_DENSITY * volume, SQUARE, thick / 2) + "\n" + "\n".join(parts)
    frames = [
        _frame(n, "square_flange", (x, 0, thick + SEAT_GAP, 0, 0, 0)) for n, x in rows.items()
    ]
    frames.append(_frame("grasp", "square_flange", _grasp_pose()))
    return _model(
        "square_flange",
        "square_flange",
        "Body frame at the flange's underside centre, between its two bosses; row_1 at -x.",
        link,
        frames,
    )


# Tray layout, tray frame at its underside centre: (name, x, y, yaw, boss x offsets in the part).
# The fingers close along each part's y, i.e. the tray's x: the square has one half to itself and
# the two ovals lie end to end on the other, so each part leaves room for the 18 mm fingers and
# the opening gap on both sides (the motion layer's tray_workaround.ROOMY_TRAY_XY).
TRAY_HOMES = [
    ("home_square_flange", -0.070, 0.0, math.pi / 2, [-SLOT_PITCH / 2, SLOT_PITCH / 2]),
    ("home_oval_flange_1", 0.060, -0.040, math.pi / 2, [0.0]),
    ("home_oval_flange_2", 0.060, 0.040, math.pi / 2, [0.0]),
]
TRAY_RIM = 0.006


def tray_sdf() -> str:
    length, width, thick = TRAY
    a, b = POCKET
    boxes = [Box("top", (length, width, thick), (0, 0, thick / 2))]
    frames = []
    for name, x0, y0, yaw, offsets in TRAY_HOMES:
        c, s = math.cos(yaw), math.sin(yaw)
        for i, dx in enumerate(offsets, start=1):
            px, py = x0 + c * dx, y0 + s * dx
            # Pocket axes in the tray frame (yaw is a multiple of 90°).
            pa, pb = (a, b) if abs(c) > 0.5 else (b, a)
            tag = f"{name.removeprefix('home_')}_{i}"
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
        frames.append(_frame(name, "tray", (x0, y0, thick + BOSS[2], 0, 0, yaw)))
    parts = [_collision_box(bx, compliant=True) for bx in boxes]
    parts += [
        _visual_box(bx, "0.25 0.6 0.35 1" if bx.name == "top" else "0.2 0.45 0.28 1")
        for bx in boxes
    ]
    link = _inertial(2.0, TRAY, thick / 2) + "\n" + "\n".join(parts)
    return _model(
        "tray",
        "tray",
        "Body frame at the tray's underside centre; a part's boss rests on the tray top.",
        link,
        frames,
    )


def table_sdf() -> str:
    thick = TABLE[2]
    top = Box("top", TABLE, (0, 0, -thick / 2))
    link = (
        _inertial(30.0, TABLE, -thick / 2)
        + "\n"
        + _collision_box(top, compliant=True)
        + "\n"
        + _visual_box(top, "0.82 0.78 0.7 1")
    )
    return _model("table", "table", "Body frame at the centre of the table top.", link, [])


def main() -> None:
    """Write every workpiece model under models/cell/."""
    files = {
        "base_plate.sdf": plate_sdf(),
        "oval_flange.sdf": oval_sdf(),
        "square_flange.sdf": square_sdf(),
        "tray.sdf": tray_sdf(),
        "table.sdf": table_sdf(),
    }
    for name, text in files.items():
        (MODELS / name).write_text(text)
        print(f"wrote {MODELS / name}")


if __name__ == "__main__":
    main()
