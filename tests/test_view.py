"""The camera that frames the cell (`hrc_drake.cell.run.view`): every framed point in Meshcat's
field of view on a 1280×800 page, as close as that allows. (The browser tests check the view in
Chromium, live and in a recording.)"""

from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.math import RigidTransform

from hrc_drake.cell.run.view import (
    MARGIN,
    PAGE_ASPECT,
    VERTICAL_FOV_DEG,
    cell_camera,
    framed_points,
)


def _frames(slots: int, plate_x: float = 0.30, pitch: float = 0.08):
    """Frames of a cell like the generated ones: seats along y on the plate at `plate_x`, three
    tray homes beside it."""
    seats = {
        k: RigidTransform([plate_x, (k - (slots + 1) / 2) * pitch, 0.02])
        for k in range(1, slots + 1)
    }
    homes = {f"part_{i}": RigidTransform([0.20 + 0.06 * i, -0.25, 0.02]) for i in range(3)}
    return SimpleNamespace(seats=seats, homes=homes)


def _view_ratios(frames) -> np.ndarray:
    """Each framed point's offset from the view's centre line over the half-angle's tangent
    (vertical, horizontal): within the view when at most 1."""
    pose = cell_camera(frames)
    forward = (pose.target - pose.position) / np.linalg.norm(pose.target - pose.position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    offsets = framed_points(frames) - pose.position
    depth = offsets @ forward
    tan_v = np.tan(np.radians(VERTICAL_FOV_DEG) / 2)
    return np.column_stack(
        [
            np.abs(offsets @ up) / depth / tan_v,
            np.abs(offsets @ right) / depth / tan_v / PAGE_ASPECT,
        ]
    )


@pytest.mark.parametrize("slots", [3, 4, 5])
def test_every_framed_point_is_in_view_and_the_camera_is_as_close_as_that_allows(slots):
    ratios = _view_ratios(_frames(slots))
    assert ratios.max() <= MARGIN + 1e-9
    assert ratios.max() >= MARGIN - 1e-6  # one point on the frame's edge: no closer camera fits


def test_a_longer_plate_moves_the_camera_back():
    """Nine slots 10 cm apart (a plate ~1 m long) need a farther camera than the flange's
    three."""
    short, long = cell_camera(_frames(3)), cell_camera(_frames(9, pitch=0.10))
    assert np.linalg.norm(long.position - long.target) > 1.2 * np.linalg.norm(
        short.position - short.target
    )
    assert _view_ratios(_frames(9, pitch=0.10)).max() <= MARGIN + 1e-9
