"""Before any simulation: does the UR3 reach every grasp the spec asks for, with room among the
parts already placed? First the occupancy rule (`hrc_drake.motion.occupancy`): every move the
spec allows keeps the planner's clearance from every part that may be in place beside it. Then
each part in its tray home and at every placement the spec allows, at the pre-grasp and the
grasp, with the robot's limits and clearance. When either fails, the error names the slot or
part, the layout value to change, and a nearby layout that passes both
(`hrc_drake.motion.reach_search`).

Apart from the planner because it plans nothing: it measures the cell's geometry and asks the
IK of each target in the empty cell, once per cell, where the planner plans a task at a time.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.ik import UnreachableError, solve_ik
from hrc_drake.motion.occupancy import CellGeometry, Crowded, check_occupancy
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.poses import CellFrames, offset_along_approach, part_pose, tcp_pose
from hrc_drake.motion.postures import toward
from hrc_drake.motion.scene import (
    GRIPPER,
    MAX_OPENING,
    PLATE,
    TRAY,
    Layout,
    SceneModel,
    load_cell_frames,
)
from hrc_drake.tasks.assembly import AssemblySpec

# A reach target: (part instance, what it is in the error, X_W_part, the layout value to change).
_Target = tuple[str, str, RigidTransform, str]


def cell_geometry(planner: MotionPlanner) -> CellGeometry:
    """The occupancy rule's view of the planner's cell (`hrc_drake.motion.occupancy`)."""
    return CellGeometry.of(planner.scene(Layout.of({}, None, MAX_OPENING)).model, planner.options)


def check_room(planner: MotionPlanner, suggest: bool = True) -> None:
    """The occupancy rule (`hrc_drake.motion.occupancy`) on the planner's cell: CellModelError
    naming the nearest move without room, the layout value to change, and with `suggest` a
    nearby layout that passes `check_reach`."""
    breaches = check_occupancy(cell_geometry(planner))
    if breaches:
        hint = _layout_hint(planner) if suggest else ""
        raise _crowded(planner, breaches, hint)


def check_reach(planner: MotionPlanner, suggest: bool = True) -> None:
    """Check, before any simulation, that every move of the spec has room among the parts that
    may be in place (`check_room`), and that the UR3 reaches every grasp (`check_grasps`).
    CellModelError naming the slot or part and the layout value to change, and with `suggest`
    a nearby layout that passed this check (`hrc_drake.motion.reach_search`)."""
    check_room(planner, suggest)
    check_grasps(planner, suggest)


def check_grasps(planner: MotionPlanner, suggest: bool = True) -> None:
    """Check that the UR3 reaches every grasp in the empty cell: each part in its tray home and
    at every placement the spec allows (pre-grasp and grasp, with the robot's limits and
    clearance). CellModelError naming the slot or part and the layout value to change, and with
    `suggest` a nearby layout that passed `check_reach`."""
    frames, opts = planner.frames, planner.options
    empty = planner.scene(Layout.of({}, None, MAX_OPENING))
    targets = _reach_targets(frames)
    # The fingers close around the part and near what it rests on; the arm must stay clear.
    near_hand = [*frames.design.instance_names, PLATE, TRAY]
    empty.set_allowed_contacts([(GRIPPER, other) for other in near_hand])
    try:
        for instance, what, X_W_part, knob in targets:
            X_grasp = tcp_pose(frames, instance, X_W_part)
            for waypoint, X in (
                ("pre-grasp", offset_along_approach(X_grasp, opts.approach_distance)),
                ("grasp", X_grasp),
            ):
                nominal = toward(empty, X.translation())
                try:
                    solve_ik(
                        empty,
                        X,
                        [nominal, planner.q_home],
                        nominal,
                        min_distance=opts.clearance,
                        task=what,
                        waypoint=waypoint,
                    )
                except UnreachableError as err:
                    hint = _layout_hint(planner) if suggest else ""
                    raise _unreachable(frames, what, waypoint, X, knob, err, hint) from err
    finally:
        empty.set_allowed_contacts(())


def _reach_targets(frames: CellFrames) -> list[_Target]:
    """Every part in its tray home, then a part of each placement's symbol at its placement
    (on its host, where it has one), in the spec's order."""
    spec = frames.spec
    targets: list[_Target] = []
    for instance, X_W_home in frames.homes.items():
        targets.append((instance, f"{instance} in its tray home", X_W_home, "cell.tray_position"))
    for token, configuration in _placement_configurations(spec).items():
        placement = spec.placement(token)
        instance = frames.design.instances_of(placement.part)[0]
        X_W_part = part_pose(frames, token, configuration | {token})
        where = f"slot {'-'.join(map(str, placement.slots))}"
        targets.append((instance, f"{token} ({where})", X_W_part, "cell.plate_position"))
    return targets


def _placement_configurations(spec: AssemblySpec) -> dict[str, frozenset[str]]:
    """Each placement token -> the tokens in place under it: none for a part on the base, its
    host's placement on the base for a part on a host."""
    configurations = {}
    for token, _mount, _slots in spec.placements():
        placement = spec.placement(token)
        if placement.host is None:
            configurations[token] = frozenset()
            continue
        host = next(
            t
            for t, m, slots in spec.placements()
            if m.part == placement.host and m.on == "base" and placement.slots[0] in slots
        )
        configurations[token] = frozenset({host})
    return configurations


def _unreachable(
    frames: CellFrames,
    what: str,
    waypoint: str,
    X: RigidTransform,
    knob: str,
    err: UnreachableError,
    hint: str,
) -> CellModelError:
    """The reach check's error: what is out of reach, where the tcp would be, and the layout
    value `knob` to change (with its value now), then `hint`."""
    now = {
        "cell.plate_position": frames.design.layout.plate_position,
        "cell.tray_position": [round(float(x), 3) for x in frames.tray.translation()],
    }
    p = X.translation()
    return CellModelError(
        f"the UR3 cannot reach {what}: {err.constraint} at the {waypoint} (tcp at "
        f"[{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m, "
        f"{float(np.hypot(p[0], p[1])):.3f} m from its base axis; it reaches "
        f"about 0.5 m). Move it closer: change {knob} (now {now[knob]})"
        f"{hint}"
    )


def _crowded(planner: MotionPlanner, breaches: list[Crowded], hint: str) -> CellModelError:
    """The occupancy rule's error: the nearest move without room (among the seats, if any is:
    a larger pitch gives room there wherever the plate stands), how many more, and the layout
    value to change (with its value now), then `hint`."""
    frames = planner.frames
    seats = [b for b in breaches if b.among_seats]
    first = (seats or breaches)[0]
    if seats:
        knob = f"cell.slot_pitch (now {frames.design.layout.slot_pitch})"
    else:
        knob = f"cell.tray_position (now {[round(float(x), 3) for x in frames.tray.translation()]})"
    more = f" (and {len(breaches) - 1} more such moves)" if len(breaches) > 1 else ""
    return CellModelError(
        f"the cell is too tight: {first.describe(frames.spec)}{more}. Give the parts room: "
        f"change {knob}{hint}"
    )


def _layout_hint(planner: MotionPlanner) -> str:
    """A layout near the planner's that passed `check_reach`, as a hint; or say none did."""
    from hrc_drake.motion.reach_search import suggest_layout

    def reaches(design: CellDesign) -> bool:
        try:
            check_reach(MotionPlanner(planner.options, design=design), suggest=False)
        except CellModelError:
            return False
        return True

    def fits(design: CellDesign) -> str | None:
        try:
            model = SceneModel(load_cell_frames(design), None)
        except CellModelError:
            return "plate_position"
        breaches = check_occupancy(CellGeometry.of(model, planner.options))
        if any(b.among_seats for b in breaches):
            return "slot_pitch"
        return "tray_position" if breaches else None

    found = suggest_layout(planner.frames.design, reaches, fits)
    if found is None:
        return (
            "; no layout near this one passed the reach check (the plate moved up to 15 cm "
            "along x, its slots up to 3 cm closer or further apart, the tray anywhere on the "
            "table, turned or not): move the plate or tray closer, or split the assembly"
        )
    return f"; the reach check passes with {found.as_yaml()} (the spec's cell: section)"
