"""Where Meshcat's camera looks: the cell framed from the operator's side.

Meshcat's default camera stands a few metres off and the cell fills a small patch of the page;
`frame_cell` puts the camera where the robot, the plate and the tray fill a 1280×800 page. It is
set with `Meshcat.SetCameraPose`, which Meshcat keeps in its scene tree, so a browser that
connects later and a recording (`Meshcat.StaticHtml`) open with the same view (the browser test
checks both, `tests/test_browser.py`). The person can still orbit and zoom from there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat

from hrc_drake.motion.poses import CellFrames

# Meshcat's default camera is a three.js PerspectiveCamera with a 75° vertical field of view
# (meshcat.js, `Viewer.create_camera`: `new PerspectiveCamera(75, 1, 0.01, 100)`).
VERTICAL_FOV_DEG = 75.0
# The page the view is framed for (wider pages see more at the sides, never less).
PAGE_ASPECT = 1280 / 800
# From the cell's centre toward the camera: in front of the robot (+x, the operator's side),
# to the side of the operator's body (-y), from above. Normalised below.
VIEW_DIRECTION = (0.70, -0.80, 0.75)
# How high the arm reaches above its base while it works (the UR3's shoulder and elbow over a
# part on the plate stay below this; the UR3's reach is 0.5 m, ur3-rg2.md).
ARM_HEIGHT = 0.55
# Parts and their seats reach this far around a seat or tray home frame (the flanges are 9 cm
# long; the tray's rim and the plate's ends a little more).
PART_REACH = 0.07
# The share of the view's half-angles the framed points may use (the rest is room around them).
MARGIN = 0.92


@dataclass(frozen=True)
class CameraPose:
    """A camera position and the point it looks at, in world (Drake's z-up) coordinates [m]."""

    position: np.ndarray
    target: np.ndarray


def framed_points(frames: CellFrames) -> np.ndarray:
    """Points the view must hold (rows): the robot's base (the world origin, where the layout
    puts the UR3) and the height its arm works at, and around every plate seat and tray home
    the corners of a square `PART_REACH` from it."""
    points = [np.zeros(3), np.array([0.0, 0.0, ARM_HEIGHT])]
    corners = PART_REACH * np.array([[1, 1, 0], [1, -1, 0], [-1, 1, 0], [-1, -1, 0]])
    for X in [*frames.seats.values(), *frames.homes.values()]:
        points += list(X.translation() + corners)
    return np.array(points)


def cell_camera(frames: CellFrames) -> CameraPose:
    """The camera that frames the cell: it looks at the centre of the framed points' box along
    `VIEW_DIRECTION`, from the least distance at which every point lies within `MARGIN` of
    Meshcat's field of view on a `PAGE_ASPECT` page."""
    points = framed_points(frames)
    target = (points.min(axis=0) + points.max(axis=0)) / 2
    back = np.asarray(VIEW_DIRECTION, dtype=float)
    back /= np.linalg.norm(back)
    forward = -back
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_v = MARGIN * np.tan(np.radians(VERTICAL_FOV_DEG) / 2)
    tan_h = tan_v * PAGE_ASPECT
    offsets = points - target
    # A point at depth d + (p - t)·forward is in view when its sideways offset is at most
    # tan(half-angle) times that depth: d >= |offset·axis| / tan - offset·forward.
    depth = offsets @ forward
    needed = np.concatenate(
        [np.abs(offsets @ up) / tan_v - depth, np.abs(offsets @ right) / tan_h - depth]
    )
    distance = max(float(needed.max()), 0.3)
    return CameraPose(position=target + distance * back, target=target)


def frame_cell(meshcat: Meshcat, frames: CellFrames) -> CameraPose:
    """Point `meshcat`'s camera at the cell (`cell_camera`); returns the pose set."""
    pose = cell_camera(frames)
    meshcat.SetCameraPose(pose.position, pose.target)
    return pose


__all__ = ["CameraPose", "cell_camera", "frame_cell", "framed_points"]
