"""Where Meshcat's camera looks: the cell framed from the operator's side.

Meshcat's default camera stands a few metres off and the cell fills a small patch of the page;
`frame_cell` puts the camera where the robot, the plate and the tray fill a 1280×800 page. It is
set with `Meshcat.SetCameraPose`, which Meshcat keeps in its scene tree, so a browser that
connects later and a recording (`Meshcat.StaticHtml`) open with the same view (the browser test
checks both, `tests/test_browser.py`). The person can still orbit and zoom from there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.geometry import Meshcat

from hrc_drake.cell.controller.keep_clear import VIEW_TIMES
from hrc_drake.motion.poses import CellFrames

if TYPE_CHECKING:
    from hrc_drake.cell.controller.supervisor import SupervisorStatus

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


_LAMPS = {"moving": (0.1, 0.8, 0.2), "slowed": (1.0, 0.7, 0.0), "stopped": (0.9, 0.1, 0.1)}


class StackLight:
    """The speed the separation monitor allows over time (`changes`), and with Meshcat a stack
    light beside the robot (also in recordings): green for the plan's own speed, amber while the
    monitor slows the robot, red while it stops it."""

    def __init__(self, meshcat):
        from pydrake.geometry import Cylinder, Rgba, Sphere
        from pydrake.math import RigidTransform

        self.meshcat, self.state = meshcat, None
        self.changes: list[tuple[float, str]] = []
        if meshcat is None:
            return
        meshcat.SetObject("/safety/pole", Cylinder(0.008, 0.3), Rgba(0.3, 0.3, 0.3, 1.0))
        meshcat.SetTransform("/safety/pole", RigidTransform([-0.15, 0.25, 0.15]))
        for k, (name, rgb) in enumerate(_LAMPS.items()):
            meshcat.SetObject(f"/safety/{name}", Sphere(0.025), Rgba(*rgb, 1.0))
            meshcat.SetTransform(f"/safety/{name}", RigidTransform([-0.15, 0.25, 0.32 + 0.055 * k]))
            meshcat.SetProperty(f"/safety/{name}", "visible", False, 0.0)

    def show(self, status: SupervisorStatus, now: float) -> None:
        """Light the lamp of the robot's state at `now` (recorded at that time)."""
        # The speed the monitor allows, also during the hold (a monitored stop: red while the
        # person is within S_p of the still robot).
        state = "moving"
        if status.clock.speed < 1.0 - 1e-9:
            state = "stopped" if status.clock.speed <= 1e-9 else "slowed"
        if state == self.state:
            return
        self.state = state
        self.changes.append((round(now, 3), state))
        if self.meshcat is None:
            return
        for name in _LAMPS:
            self.meshcat.SetProperty(f"/safety/{name}", "visible", name == state, now)


class ForecastView:
    """With Meshcat (also in recordings): the controller's forecast of the operator's hand
    over the next three seconds as translucent amber spheres, drawn each time the robot times
    its plan around it (predictive separation)."""

    RADIUS = 0.06  # m: the hand and the forecast's uncertainty

    def __init__(self, meshcat, count: int):
        from pydrake.geometry import Rgba, Sphere

        self.meshcat, self.shown = meshcat, ()
        for k in range(count):
            meshcat.SetObject(f"/forecast/{k}", Sphere(self.RADIUS), Rgba(1.0, 0.6, 0.1, 0.25))
            meshcat.SetProperty(f"/forecast/{k}", "visible", False, 0.0)

    def show(self, status: SupervisorStatus, now: float) -> None:
        """Draw the forecast of `status` when it changed (recorded at `now`)."""
        from pydrake.math import RigidTransform

        view = status.clear.forecast_view if status.plan is not None else ()
        if view == self.shown:
            return
        self.shown = view
        for k, point in enumerate(view):
            self.meshcat.SetTransform(f"/forecast/{k}", RigidTransform(list(point)), now)
            self.meshcat.SetProperty(f"/forecast/{k}", "visible", True, now)
        for k in range(len(view), len(VIEW_TIMES)):
            self.meshcat.SetProperty(f"/forecast/{k}", "visible", False, now)


__all__ = ["CameraPose", "ForecastView", "StackLight", "cell_camera", "frame_cell", "framed_points"]
