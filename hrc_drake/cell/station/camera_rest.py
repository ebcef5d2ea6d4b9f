"""The camera's evidence that a part rests on its seat floor: its frames averaged while it
stays still (`configuration: camera`; `hrc_drake.cell.station.camera`).

One frame cannot tell a seated part from one that debris holds a millimetre up. A square flange
lowered onto 3 mm of debris under one of its bosses rests 1.16 mm high, tilted 0.023 rad
(measured: `hrc-drake simulate --scenario row1-optimal` with `faults: [!NoSeat {task: 2,
obstacle: true}]`), inside what a frame's verdict allows: the pocket's 1 mm and 0.03 rad
(`SlotTolerances`) and three noise standard deviations more. A part resting on its floor stands
at the seat's plane (0.00-0.01 mm measured, the hydroelastic penetration). So the camera
keeps, for each part, its estimates since the part last moved (`Still`, up to WINDOW frames),
decides every verdict from their mean, and reads a part seated only when the mean of at least
SEAT_FRAMES of them stands within REST_HEIGHT of the seat's plane, plus K_SIGMA standard
deviations of the mean's noise (`rests`). Before it has those frames a seated look is
tentative: it changes no reported verdict (`follow(..., tentative=True)`), and the reading's
stamp waits for it, even where the part is already reported there (it may have moved off and
back: a part let go beside its seat).

At the camera's 0.3 mm (`hrc_drake.scenario.sensors.CAMERA`) the bound is 0.87 mm after 6
frames and 0.76 mm after 12, under the debris's 1.16 mm by 2.4 and 4 standard deviations of the
mean; at 5 Hz the 6 frames take 1.2 s after the part comes to rest.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix

from hrc_drake.cell.ports import PartPlacement, PartStatus
from hrc_drake.cell.station.camera_verdicts import (
    K_SIGMA,
    CameraTolerances,
    Verdict,
    follow,
    frame_placements,
    radial_quantile,
)
from hrc_drake.cell.station.slot_monitor import SeatGeometry, rotation_angle
from hrc_drake.motion.poses import seat_pose

# m: how far above its seat's plane a part resting on the floor may be read: the hydroelastic
# penetration (under 0.01 mm, measured), a camera's calibration of the plate (our assumption:
# a few tenths of a millimetre) and room to spare, under the 1.16 mm debris holds a part up.
REST_HEIGHT = 0.0005
# Frames averaged before the camera reads a part seated, and at most.
SEAT_FRAMES = 6
WINDOW = 12
# A new estimate farther than this many standard deviations (of the 3-D difference, in position
# or in orientation) from the still part's mean says the part moved: 1.5e-5 of the draws of one
# that did not (the Maxwell tail at 5).
K_MOVED = 5.0
# A move too small for one estimate to show (the operator's hand setting a part a millimetre
# lower) shows in the mean of the newest SHIFT_FRAMES against the older ones' mean: past this
# many standard deviations of their difference (5e-4 of the draws of a part that did not move),
# the older ones are dropped. The debris's 1.16 mm shows once 3 new frames stand against 9 or
# more (bound 0.84 mm): at most 3 frames after the move still read the part as before.
SHIFT_FRAMES = 3
K_SHIFT = 3.5
_SHIFT_RADIUS = radial_quantile(K_SHIFT, 3)


def _rotation_vector(R: RotationMatrix) -> np.ndarray:
    aa = R.ToAngleAxis()
    return aa.angle() * aa.axis()


def rotation_from_vector(vector: np.ndarray) -> RotationMatrix:
    """The rotation by the rotation vector `vector` [rad]."""
    angle = float(np.linalg.norm(vector))
    if angle == 0.0:
        return RotationMatrix()
    return RotationMatrix(AngleAxis(angle, vector / angle))


def mean_pose(poses: tuple[RigidTransform, ...]) -> RigidTransform:
    """The mean of `poses` that lie close together: their positions' mean, and the first's
    orientation turned by the mean of the others' rotation vectors from it."""
    first = poses[0].rotation()
    turns = np.mean([_rotation_vector(first.inverse() @ X.rotation()) for X in poses], axis=0)
    position = np.mean([X.translation() for X in poses], axis=0)
    return RigidTransform(first @ rotation_from_vector(turns), position)


@dataclass(frozen=True)
class Still:
    """A part's estimates since it last moved (the newest WINDOW), and their mean."""

    poses: tuple[RigidTransform, ...] = ()
    mean: RigidTransform = field(default_factory=RigidTransform)

    @property
    def frames(self) -> int:
        """How many estimates the mean is of."""
        return len(self.poses)

    def add(self, X: RigidTransform, noise: float, angle_noise: float) -> Still:
        """With the new estimate `X` (of a camera of that `noise` [m] and `angle_noise` [rad]
        per axis): appended, or alone when it says the part moved."""
        if not self.poses or _apart(
            self.mean, X, K_MOVED, 1.0 + 1.0 / self.frames, noise, angle_noise
        ):
            return Still((X,), X)
        poses = (*self.poses, X)[-WINDOW:]
        older, recent = poses[:-SHIFT_FRAMES], poses[-SHIFT_FRAMES:]
        if len(older) >= SHIFT_FRAMES:
            variance = 1.0 / len(recent) + 1.0 / len(older)
            recent_mean = mean_pose(recent)
            if _apart(mean_pose(older), recent_mean, _SHIFT_RADIUS, variance, noise, angle_noise):
                return Still(recent, recent_mean)
        return Still(poses, mean_pose(poses))


def _apart(
    X_a: RigidTransform, X_b: RigidTransform, radius: float, variance: float, noise, angle_noise
) -> bool:
    """Whether two estimates whose difference has `variance` times a frame's noise variance
    lie farther apart than `radius` standard deviations of it, in position or in
    orientation."""
    spread = radius * math.sqrt(variance)
    distance, angle = rotation_angle(X_a, X_b)
    return distance > spread * noise or angle > spread * angle_noise


def rest_bound(noise: float, frames: int, host_frames: int | None = None) -> float:
    """How high [m] above its seat's plane a part may be read resting on the floor, from the
    mean of `frames` estimates (and, on a host's row, of `host_frames` of the host's)."""
    variance = 1.0 / frames + (1.0 / host_frames if host_frames else 0.0)
    return REST_HEIGHT + K_SIGMA * noise * math.sqrt(variance)


def seat_height(
    g: SeatGeometry,
    placement: PartPlacement,
    X: RigidTransform,
    means: Mapping[str, RigidTransform],
    X_W_plate: RigidTransform,
) -> float:
    """The height [m] of the pose `X` above the plane of the seat its `placement` names (a
    plate seat: its slots'; a host's row: the row on the host's pose in `means`)."""
    if placement.host:
        rows = dict(dict(g.hosts)[placement.host])
        X_W_seat = means[placement.host] @ rows[placement.seats[0]]
    else:
        slots = dict(g.slots)
        X_W_seat = seat_pose({k: X_W_plate @ slots[k] for k in placement.slots}, placement.slots)
    return abs(float(X_W_seat.InvertAndCompose(X).translation()[2]))


def rests(
    g: SeatGeometry,
    placement: PartPlacement,
    part: str,
    stills: Mapping[str, Still],
    means: Mapping[str, RigidTransform],
    X_W_plate: RigidTransform,
    noise: float,
    need: int = SEAT_FRAMES,
) -> bool | None:
    """Whether the part a frame reads seated (`placement`) rests on that seat's floor, by the
    mean of its still estimates (`means`: each part's `stills` mean; module docstring); None:
    fewer than `need` of them yet."""
    host = placement.host
    frames = stills[part].frames
    host_frames = stills[host].frames if host else None
    if frames < need or (host_frames is not None and host_frames < need):
        return None
    height = seat_height(g, placement, means[part], means, X_W_plate)
    return height <= rest_bound(noise, frames, host_frames)


@dataclass(frozen=True)
class CameraViews:
    """What the camera keeps of each part from frame to frame: its verdict and its still
    estimates."""

    verdicts: dict[str, Verdict]
    stills: dict[str, Still]


def see(
    g: SeatGeometry,
    t: CameraTolerances,
    noise: tuple[float, float],
    previous: CameraViews | None,
    poses: Mapping[str, RigidTransform],
    X_W_plate: RigidTransform,
    X_W_tcp: RigidTransform | None,
) -> CameraViews:
    """The views after a frame of estimated `poses` (`noise`: the camera's, position [m] and
    angle [rad]), given the `previous` ones (None: the first frame, whose views are taken as
    settled: the camera ran before). Every verdict is the frame's on the still parts' means
    (`frame_placements`); a seated one is kept only where the part `rests` on its floor, and is
    tentative while too few frames tell."""
    before = previous.stills if previous is not None else {}
    stills = {p: before.get(p, Still()).add(X, *noise) for p, X in poses.items()}
    means = {p: s.mean for p, s in stills.items()}
    seen = frame_placements(g, t, means, X_W_plate, X_W_tcp)
    need = 1 if previous is None else SEAT_FRAMES
    rest = {
        p: rests(g, seen[p], p, stills, means, X_W_plate, noise[0], need)
        for p in seen
        if seen[p].status == PartStatus.SEATED
    }
    lifted = frozenset(p for p, r in rest.items() if r is False)
    if lifted:
        seen = frame_placements(g, t, means, X_W_plate, X_W_tcp, lifted)
    verdicts = previous.verdicts if previous is not None else {}
    return CameraViews(
        {p: follow(verdicts.get(p), seen[p], tentative=rest.get(p, True) is None) for p in seen},
        stills,
    )


__all__ = [
    "K_MOVED",
    "K_SHIFT",
    "REST_HEIGHT",
    "SEAT_FRAMES",
    "SHIFT_FRAMES",
    "WINDOW",
    "CameraViews",
    "Still",
    "mean_pose",
    "rest_bound",
    "rests",
    "rotation_from_vector",
    "seat_height",
    "see",
]
