"""Grasping a part lying loose where the cell measured it (after a drop, or a part that did not
seat): the grasps it offers, the first of them the wrist reaches, whether the fingers' way down
to it is clear, and what it rests on.

Apart from the planner because a part in its tray home or at its seat has one known grasp, clear
by the cell's design; these are the rules and checks for a part lying anywhere else.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from hrc_drake.cell_models import TABLE
from hrc_drake.motion.ik import UnreachableError
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.poses import CellFrames, offset_along_approach, tcp_pose
from hrc_drake.motion.scene import GRIPPER, MAX_OPENING, PLATE, TRAY, PlanningScene

# A loose part lying tilted up to this from upright [rad] is grasped with the gripper tilted to
# the part's normal (its own grasp frame where it lies): the fingers close across the part's
# width, square to its faces, as in the tray. Past it the approach leans so far that the
# fingers going down along it meet what the part leans on, and the wrist's posture comes close
# to the UR3's reach over the plate; the part is handed over. (It was 0.2 rad, with a vertical
# approach in mind: a flange resting 0.21 rad tilted against the plate's edge was handed over.)
_MAX_GRASP_TILT = 0.5
# A loose part rests on, or leans against, what is this close to it [m] (measured poses are
# a little off: a part may seem to float or sink by a millimetre or two).
_RESTS_ON = 0.005

# The planner's IK: (scene, X_W_tcp, previous posture, task, waypoint) -> joint positions.
SolveIK = Callable[[PlanningScene, RigidTransform, np.ndarray, str, str], np.ndarray]


def loose_grasps(
    frames: CellFrames, options: MotionOptions, task: str, part: str, X_W_part: RigidTransform
) -> tuple[RigidTransform, ...]:
    """The tcp poses grasping `part` lying at a measured X_W_part: its grasp frame there,
    and that turned a half turn about the approach axis (the parts are symmetric under it),
    the one closer to the grasp at the part's tray home first, so that the wrist does not
    wind; the other is tried when the first is out of reach (a tilted grasp often is).
    The grasp tilts with the part (up to `_MAX_GRASP_TILT`), so the fingers close across
    its width as in the tray; UnreachableError when the part lies more tilted, or is
    wider than the gripper's stroke (its IK and the fingers' way down are checked after)."""
    X_W_home = frames.homes[part]
    up = X_W_home.rotation().col(2)  # a part lies upright in its tray home
    tilt = float(np.arccos(np.clip(X_W_part.rotation().col(2) @ up, -1.0, 1.0)))
    if tilt > _MAX_GRASP_TILT:
        raise UnreachableError(
            task,
            "grasp",
            "orientation",
            f"{part} lies tilted {tilt:.2f} rad from upright; the gripper grasps a loose "
            f"part tilted with it, up to {_MAX_GRASP_TILT} rad",
        )
    width = frames.widths[part] + 2.0 * options.finger_gap
    if width > MAX_OPENING:  # the width across the grasp is the part's, at any tilt
        raise UnreachableError(
            task,
            "grasp",
            "stroke",
            f"{part} needs {width * 1000:.0f} mm between the fingers, past the RG2's "
            f"{MAX_OPENING * 1000:.0f} mm stroke",
        )
    X_grasp = tcp_pose(frames, part, X_W_part)
    turned = X_grasp @ RigidTransform(RotationMatrix.MakeZRotation(np.pi))
    R_home_inv = tcp_pose(frames, part, X_W_home).rotation().inverse()

    def wind(X: RigidTransform) -> float:
        return (R_home_inv @ X.rotation()).ToAngleAxis().angle()

    # Both hold the part in its own grasp frame, so that the place half (which seats the
    # part held so) serves them. A level grasp straddling a tilted part would hold it tilted
    # between the fingers and seat it so: not offered.
    return tuple(sorted((X_grasp, turned), key=wind))


def loose_supports(scene: PlanningScene, frames: CellFrames, part: str) -> tuple[str, ...]:
    """What a loose part may rest on or lean against, as model instances: the table, the
    plate or the tray, or other parts within `_RESTS_ON` of it."""
    others = [i for i in frames.design.instance_names if i != part]
    return (PLATE, TRAY, TABLE, *scene.near(part, others, _RESTS_ON))


def reach_loose(
    ik: SolveIK,
    options: MotionOptions,
    scene: PlanningScene,
    candidates: Sequence[RigidTransform],
    q_start: np.ndarray,
    task: str,
):
    """(grasp, pre-grasp, posture there) of the first of a loose part's grasps (in order)
    whose pre-grasp the wrist reaches: at the approach distance, else at half of it (a
    tilted grasp's approach leans, and backing off along it soon takes the tcp past the
    UR3's reach: a flange resting 0.39 rad tilted on the plate's edge is reached 30 mm back,
    not 60). UnreachableError from the last tried when none is."""
    distance = options.approach_distance
    tries = [(X, d) for d in (distance, distance / 2) for X in candidates]
    for k, (X_grasp, d) in enumerate(tries, start=1):
        X_pregrasp = offset_along_approach(X_grasp, d)
        try:
            return X_grasp, X_pregrasp, ik(scene, X_pregrasp, q_start, task, "pre-grasp")
        except UnreachableError:
            if k == len(tries):
                raise
    raise AssertionError("unreachable")  # the loop returns or raises


def check_fingers_clear(scene: PlanningScene, part: str, down: list, task: str) -> None:
    """UnreachableError when, at the postures `down` going to a part lying loose (at the
    scene's opening), the gripper would touch what the part lies on or beside (allowed near
    it, not into it: a part lying askew on the tray may leave no room for a finger beside it)."""
    scene.set_allowed_contacts(((GRIPPER, part),))
    for q in down:
        gap, pair = scene.min_distance(q, max_distance=0.01)
        if gap <= 0.0 and GRIPPER in pair:
            raise UnreachableError(
                task,
                "grasp",
                "collision",
                f"{part} lies where the fingers, going down to it or closing on it, would "
                f"touch the cell ({pair})",
            )
