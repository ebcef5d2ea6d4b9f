"""A layout the UR3 reaches with room for every move, to suggest when the one given fails.

`check_reach` (`hrc_drake.motion.reach_check`) fails on a layout whose tray or plate is too far,
or whose parts stand too close for the gripper (the occupancy rule,
`hrc_drake.motion.occupancy`). Guessing the fix (a smaller `slot_pitch`, a tray position found
by trial) is not a hint: here candidate layouts near the given one are generated — the plate
moved along the robot's x and its slots closer together or further apart, the tray anywhere on
the table, turned as given or a quarter turn more — screened on plain geometry (every target
within the UR3's reach of its base axis, the tray and the plate apart, on the table and clear of
the robot's base), then by the occupancy rule (`fits`), then checked with the reach check
itself, nearest first, until one passes. Only a layout that passed is suggested.

The caller passes `reaches(design) -> bool` (the reach check on a design) and
`fits(design) -> str | None` (the occupancy rule: None, or the layout key whose change gives
room), so this module does not import the planner.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Iterable

import numpy as np

from hrc_drake.cell_models import TABLE_HALF, TABLE_POSITION, CellDesign
from hrc_drake.layout import CellLayout
from hrc_drake.workpiece_sdf import PLATE_END, PLATE_WIDTH, slot_offsets

# Horizontal distance from the UR3's base axis within which a grasp with the tool pointing down
# passed the reach check in a scan of tray positions (0.494 m passed, 0.511 m failed; the UR3's
# catalogue reach is 0.5 m, shared/reference/ur3-rg2.md). Screening only: the check decides.
REACH = 0.49
# Nearer than this the arm folds over its own base; the tray and the plate keep clear of it.
NEAR = 0.15
BASE_CLEARANCE = 0.10
GAP = 0.015  # between the tray and the plate (the default `tray_gap`)
# Reach checks tried at most (each builds a planner, about 0.4 s).
BUDGET = 12
# Occupancy screens tried at most (each reads a cell's geometry, about 0.35 s).
FIT_BUDGET = 40
# Plate moves and slot pitch changes tried, each way: 6 steps of 2.5 cm and of 5 mm.
STEPS = 6
X_STEP, PITCH_STEP = 0.025, 0.005
# A tray turned a quarter turn from the given one ranks as if moved this far [m].
TURN_COST = 0.1

Reaches = Callable[[CellDesign], bool]
Fits = Callable[[CellDesign], "str | None"]


@dataclasses.dataclass(frozen=True)
class Suggestion:
    """A layout that passed the reach check, and the `cell:` keys that differ from the given."""

    layout: CellLayout
    changes: dict

    def as_yaml(self) -> str:
        """The changed keys as one line of YAML for a spec's (or scenario's) `cell:` section."""
        items = ", ".join(f"{k}: {_yaml_value(v)}" for k, v in self.changes.items())
        return f"cell: {{{items}}}"


def _yaml_value(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return f"{value:g}"


def _rectangle(center, yaw_deg: float, length: float, width: float) -> np.ndarray:
    """Corners (4 x 2) of a length x width rectangle turned by yaw about z at center."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    half = [(length / 2, width / 2), (-length / 2, width / 2)]
    corners = [(x, y) for x, y in half] + [(-x, -y) for x, y in half]
    return np.array([[center[0] + c * x - s * y, center[1] + s * x + c * y] for x, y in corners])


def _apart(a: np.ndarray, b: np.ndarray, gap: float) -> bool:
    """Whether two convex polygons are at least `gap` apart along some edge normal."""
    for poly in (a, b):
        for i in range(len(poly)):
            edge = poly[(i + 1) % len(poly)] - poly[i]
            normal = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
            pa, pb = a @ normal, b @ normal
            if pa.max() + gap <= pb.min() or pb.max() + gap <= pa.min():
                return True
    return False


def _within(points: Iterable, near: float = NEAR, far: float = REACH) -> bool:
    return all(near <= math.hypot(p[0], p[1]) <= far for p in points)


def _on_table(corners: np.ndarray) -> bool:
    return bool(np.all(np.abs(corners - np.array(TABLE_POSITION[:2])) <= TABLE_HALF))


def _clear_of_base(corners: np.ndarray) -> bool:
    # The base axis is at the origin: keep a disc of BASE_CLEARANCE free.
    disc = _rectangle((0.0, 0.0), 0.0, 2 * BASE_CLEARANCE, 2 * BASE_CLEARANCE)
    return _apart(corners, disc, 0.0)


def _plate(design: CellDesign) -> tuple[np.ndarray, list]:
    """The plate's corners and its slot centres in world (x, y)."""
    layout = design.layout
    X = design.X_W_plate()
    length = layout.slot_pitch * (design.slots - 1) + 2 * PLATE_END
    corners = _rectangle(layout.plate_position, layout.plate_yaw_deg, length, PLATE_WIDTH)
    slots = [X @ np.array([x, 0.0, 0.0]) for x in slot_offsets(design.slots, layout.slot_pitch)]
    return corners, slots


def _tray(design: CellDesign, position=None) -> tuple[np.ndarray, list]:
    """The tray's corners and its homes in world (x, y), where the layout puts it or at
    `position`."""
    homes, (length, width, _) = design.tray()
    yaw = design.layout.plate_yaw_deg + design.layout.tray_yaw_deg
    center = design.X_W_tray().translation() if position is None else position
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    points = [(center[0] + c * h.x - s * h.y, center[1] + s * h.x + c * h.y) for h in homes]
    return _rectangle(center, yaw, length, width), points


def plausible(design: CellDesign, tray_position=None) -> bool:
    """The geometric screen: every slot and tray home within reach, tray and plate apart, both
    on the table and clear of the robot's base (the tray at `tray_position` if given)."""
    plate, slots = _plate(design)
    tray, homes = _tray(design, tray_position)
    return (
        _within(slots)
        and _within(homes)
        and _apart(plate, tray, GAP)
        and all(_on_table(c) and _clear_of_base(c) for c in (plate, tray))
    )


def _tray_options(design: CellDesign) -> list[tuple[float, list[float]]]:
    """(tray_yaw_deg, tray position) on a 2.5 cm grid over the table, the tray as given and
    turned a quarter turn, nearest to the current one first, keeping only those whose homes
    are all within reach (the rest of the screen is `plausible`'s)."""
    here = design.X_W_tray().translation()
    z = float(here[2])
    grid = np.arange(-0.5, 0.5001, 0.025)
    xy = np.array([[TABLE_POSITION[0] + x, y] for x, y in itertools.product(grid, grid)])
    homes, _size = design.tray()
    given = design.layout.tray_yaw_deg
    options = []
    for yaw in (given, given + 90.0 if given < 0 else given - 90.0):
        turn = math.radians(design.layout.plate_yaw_deg + yaw)
        c, s = math.cos(turn), math.sin(turn)
        offsets = np.array([[c * h.x - s * h.y, s * h.x + c * h.y] for h in homes])
        reach = np.linalg.norm(xy[:, None, :] + offsets[None], axis=2)
        ok = np.all((reach >= NEAR) & (reach <= REACH), axis=1)
        cost = np.hypot(xy[:, 0] - here[0], xy[:, 1] - here[1]) + (TURN_COST if yaw != given else 0)
        for k in np.flatnonzero(ok):
            position = [round(float(xy[k, 0]), 3), round(float(xy[k, 1]), 3), z]
            options.append((float(cost[k]), round(yaw, 6), position))
    return [(yaw, position) for _cost, yaw, position in sorted(options)]


def _plate_candidates(layout: CellLayout) -> list[CellLayout]:
    """The plate moved along the robot's x (2.5 cm steps) and/or its slots closer together or
    further apart (5 mm steps), smallest change first."""
    x0, pitch0 = layout.plate_position[0], layout.slot_pitch
    xs = [x0 + X_STEP * k for k in range(-STEPS, STEPS + 1)]
    pitches = [
        round(pitch0 + PITCH_STEP * k, 3)
        for k in range(-STEPS, STEPS + 1)
        if 0.05 <= pitch0 + PITCH_STEP * k <= 0.3
    ]
    pairs = sorted(
        itertools.product(xs, pitches),
        key=lambda xp: (abs(xp[0] - x0) / X_STEP + abs(xp[1] - pitch0) / PITCH_STEP, -xp[1]),
    )
    out = []
    for x, pitch in pairs:
        position = [round(x, 3), *layout.plate_position[1:]]
        out.append(dataclasses.replace(layout, plate_position=position, slot_pitch=pitch))
    return out


def _with_tray(design: CellDesign) -> CellDesign | None:
    """`design` as is if it passes the screen, else with the nearest tray position (and turn)
    that does."""
    if plausible(design):
        return design
    _plate_corners, slots = _plate(design)
    if not _within(slots):
        return None  # no tray position helps a plate out of reach
    for yaw, position in _tray_options(design):
        layout = dataclasses.replace(design.layout, tray_yaw_deg=yaw, tray_position=position)
        moved = CellDesign.of(design.spec, layout)
        if plausible(moved):
            return moved
    return None


def _changes(before: CellLayout, after: CellLayout) -> dict:
    keys = ("plate_position", "slot_pitch", "tray_position", "tray_yaw_deg")
    return {k: getattr(after, k) for k in keys if getattr(after, k) != getattr(before, k)}


def suggest_layout(
    design: CellDesign,
    reaches: Reaches,
    fits: Fits | None = None,
    budget: int = BUDGET,
) -> Suggestion | None:
    """The nearest layout to `design`'s that passes the screen, then `fits` and then
    `reaches`: the plate moved and/or its slots closer together or further apart (with the
    tray beside it where that fits, else moved and perhaps turned); None if none of `budget`
    reach checks (and `FIT_BUDGET` occupancy screens) passed.

    A pitch whose parts crowd each other on the plate (`fits` answers `slot_pitch`) crowds
    them at any plate position and at any smaller pitch (the slots part faster than the parts
    grow): such pitches are not tried again."""
    layout = design.layout
    tried = screened = 0
    tight = 0.0  # pitches up to this one crowd the plate
    for candidate in _plate_candidates(layout):
        if candidate.slot_pitch <= tight + 1e-9:
            continue
        found = _with_tray(CellDesign.of(design.spec, candidate))
        if found is None or found.layout.key() == layout.key():
            continue
        if fits is not None:
            if screened >= FIT_BUDGET:
                break
            screened += 1
            knob = fits(found)
            if knob == "slot_pitch":
                tight = max(tight, candidate.slot_pitch)
            if knob is not None:
                continue
        tried += 1
        if reaches(found):
            return Suggestion(found.layout, _changes(layout, found.layout))
        if tried >= budget:
            break
    return None
