"""Before any simulation: does the UR3 reach every grasp the spec asks for? Each part in its tray
home and at every placement the spec allows, at the pre-grasp and the grasp, with the robot's
limits and clearance. When it does not, the error names the slot or part, the layout value to
change, and a nearby layout that passes (`hrc_drake.motion.reach_search`).

Apart from the planner because it plans nothing: it asks the IK of each target in the empty
cell, once per cell, where the planner plans a task at a time.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion.ik import UnreachableError, solve_ik
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.poses import CellFrames, offset_along_approach, part_pose, tcp_pose
from hrc_drake.motion.postures import toward
from hrc_drake.motion.scene import GRIPPER, MAX_OPENING, PLATE, TRAY, Layout
from hrc_drake.tasks.assembly import AssemblySpec

# A reach target: (part instance, what it is in the error, X_W_part, the layout value to change).
_Target = tuple[str, str, RigidTransform, str]


def check_reach(planner: MotionPlanner, suggest: bool = True) -> None:
    """Check, before any simulation, that the UR3 reaches every grasp: each part in its tray home
    and at every placement the spec allows (pre-grasp and grasp, with the robot's limits and
    clearance). CellModelError naming the slot or part and the layout value to change, and with
    `suggest` a nearby layout that passed this check (`hrc_drake.motion.reach_search`)."""
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


def _layout_hint(planner: MotionPlanner) -> str:
    """A layout near the planner's that passed `check_reach`, as a hint; or say none did."""
    from hrc_drake.motion.reach_search import suggest_layout

    def reaches(design: CellDesign) -> bool:
        try:
            check_reach(MotionPlanner(planner.options, design=design), suggest=False)
        except CellModelError:
            return False
        return True

    found = suggest_layout(planner.frames.design, reaches)
    if found is None:
        return "; no layout near this one passed the reach check: move the plate or tray closer"
    return f"; the reach check passes with {found.as_yaml()} (the spec's cell: section)"
