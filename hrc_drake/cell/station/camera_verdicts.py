"""The camera's verdicts: where each part is, decided from estimated part poses alone, with no
contact (`configuration: camera`, `hrc_drake.cell.station.camera`).

A frame gives each part's estimated pose, with Gaussian noise of `noise` [m] on each coordinate
and `angle_noise` [rad] about each axis (`hrc_drake.scenario.sensors.CAMERA`). Its verdicts are
the SlotMonitor's (`hrc_drake.cell.station.slot_monitor`), in the same order, with the contact
tests replaced by poses and every tolerance widened by what the noise adds (`CameraTolerances`):

- **seated**: the pose is within the pocket's tolerance (`SlotTolerances`) plus K_SIGMA noise
  standard deviations of a seat: a seat of the plate (its pose known from the cell's
  calibration), or a row of a host part (where the camera sees the host: its noise and the
  part's add, so sqrt(2) times the noise). The token is the spec's for those slots.
- **held**: the part's grasp frame is within the SlotMonitor's held tolerance (plus the noise)
  of the gripper's tcp, which the arm's joint measurements give (an encoder step moves the tool
  by some 0.05 mm: taken as exact).
- **misplaced**: over the plate or a host part, resting on it (its body frame at most
  `REST_ABOVE` above the seat plane), in no seat.
- **tray**, else **transit**, as the SlotMonitor.

A part's reported verdict changes only when CONFIRM_FRAMES frames in a row agree on the new one
(`follow`): a single frame beyond a K_SIGMA bound (0.27 % of a Gaussian's draws) flips nothing.

What the noise is allowed to be (`max_noise`): a part whose boss stands on a pocket's rim is
POCKET_DEPTH (4 mm) high, a seated one at most `SlotTolerances.seat_z` (1 mm); one frame tells
them apart with K_SIGMA on both sides while 2·K_SIGMA·sqrt(2)·noise (a row of a host: two
estimates) fits between: noise <= 0.35 mm. A noisier camera is refused when the station is
built. The orientation's noise must keep the yaw tolerance under a quarter of a half turn.

What one frame cannot tell, a part seated from one held a millimetre up by debris, the camera
tells from the mean of a still part's frames (`hrc_drake.cell.station.camera_rest`): the frame
verdicts here are taken on those means, and a seated one is kept only where the mean rests on
the seat's floor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.cell.ports import PartPlacement, PartStatus
from hrc_drake.cell.station.slot_monitor import (
    SeatGeometry,
    SlotTolerances,
    pose_error,
    rotation_angle,
)
from hrc_drake.motion.poses import seat_pose
from hrc_drake.workpiece_sdf import HOST_END, HOST_WIDTH, PLATE_END, PLATE_WIDTH, POCKET_DEPTH

# A noise bound a Gaussian error passes 0.27 % of the time along one axis.
K_SIGMA = 3.0
# Frames in a row that must agree before a part's verdict changes.
CONFIRM_FRAMES = 3
# A part resting on the plate or a host lies within this of its seat plane (its body frame:
# flat on its boss 4 mm, upside down 10-16 mm, on its edge half its width, 22-45 mm).
REST_ABOVE = 0.05  # m
# ... and reaches this far past the surface's edges (a part hanging over them).
REST_MARGIN = 0.02  # m


def _tail(k: float) -> float:
    """The probability that a Gaussian error passes k standard deviations (either side)."""
    return math.erfc(k / math.sqrt(2.0))


def radial_quantile(k: float, dof: int) -> float:
    """The radius a `dof`-dimensional standard Gaussian error (2: Rayleigh, 3: Maxwell) passes
    as often as a one-dimensional one passes `k` standard deviations."""
    p = _tail(k)
    if dof == 2:
        return math.sqrt(-2.0 * math.log(p))

    def tail3(r: float) -> float:
        return math.erfc(r / math.sqrt(2.0)) + math.sqrt(2.0 / math.pi) * r * math.exp(-r * r / 2)

    low, high = k, k + 5.0
    for _ in range(60):  # bisection: tail3 decreases with r
        mid = (low + high) / 2
        low, high = (mid, high) if tail3(mid) > p else (low, mid)
    return (low + high) / 2


@dataclass(frozen=True)
class CameraTolerances:
    """The per-frame tolerances of the camera's verdicts: the SlotMonitor's (the pocket's
    clearance, the gripper, the tray) plus K_SIGMA of the estimate's noise, with the Rayleigh
    (horizontal, tilt) or Maxwell (3-D) bound of the same tail where an error has several
    components. `host_*` are a host row's: the part's and the host's estimates, sqrt(2) the
    noise."""

    seat_xy: float
    seat_z: float
    seat_tilt: float
    seat_yaw: float
    host_xy: float
    host_z: float
    host_tilt: float
    host_yaw: float
    held_position: float
    held_angle: float
    tray_position: float
    tray_angle: float
    host_over_slot: float
    rest_below: float

    @staticmethod
    def of(
        noise: float, angle_noise: float, base: SlotTolerances | None = None, k: float = K_SIGMA
    ) -> CameraTolerances:
        """The tolerances for a camera of position `noise` [m] and `angle_noise` [rad] per
        axis, around the SlotMonitor's `base`."""
        b = base if base is not None else SlotTolerances()
        q2, q3 = radial_quantile(k, 2), radial_quantile(k, 3)
        rel, rel_angle = math.sqrt(2.0) * noise, math.sqrt(2.0) * angle_noise
        return CameraTolerances(
            seat_xy=b.seat_xy + q2 * noise,
            seat_z=b.seat_z + k * noise,
            seat_tilt=b.seat_tilt + q2 * angle_noise,
            seat_yaw=b.seat_yaw + k * angle_noise,
            host_xy=b.seat_xy + q2 * rel,
            host_z=b.seat_z + k * rel,
            host_tilt=b.seat_tilt + q2 * rel_angle,
            host_yaw=b.seat_yaw + k * rel_angle,
            held_position=b.held_position + q3 * noise,
            held_angle=b.held_angle + q3 * angle_noise,
            tray_position=b.tray_position + q3 * noise,
            tray_angle=b.tray_angle + q3 * angle_noise,
            host_over_slot=b.host_over_slot + q2 * rel,
            rest_below=POCKET_DEPTH + k * noise,
        )


def max_noise(base: SlotTolerances | None = None, k: float = K_SIGMA) -> tuple[float, float]:
    """(position [m], angle [rad]) noise the pockets support in one frame (module docstring):
    a seated part and one on a pocket's rim told apart at `k` sigma on both sides, on a host's
    row too; the yaw tolerance under pi/4."""
    b = base if base is not None else SlotTolerances()
    position = (POCKET_DEPTH - b.seat_z) / (2 * k * math.sqrt(2.0))
    angle = (math.pi / 4 - b.seat_yaw) / (k * math.sqrt(2.0))
    return position, angle


def check_camera_noise(noise: float, angle_noise: float, key: str = "sensors.camera") -> None:
    """ValueError in one line naming `key.noise` or `key.angle_noise` for more noise than the
    pockets support (`max_noise`)."""
    position, angle = max_noise()
    if noise > position + 1e-12:
        raise ValueError(
            f"{key}.noise: {noise} m is more than the {position:.5f} m the pockets support in "
            f"one frame (a part on a pocket's rim is {POCKET_DEPTH * 1000:g} mm high); give "
            "at most that"
        )
    if angle_noise > angle + 1e-12:
        raise ValueError(
            f"{key}.angle_noise: {angle_noise} rad is more than the {angle:.3f} rad the "
            "pockets support; give at most that"
        )


def _within(X_seat: RigidTransform, X: RigidTransform, xy, z, tilt, yaw) -> bool:
    e_xy, e_z, e_tilt, e_yaw = pose_error(X_seat, X)
    return e_xy <= xy and e_z <= z and e_tilt <= tilt and e_yaw <= yaw


def _base_seat(g: SeatGeometry, t: CameraTolerances, part, X, seats) -> PartPlacement | None:
    span = g.spans[part]
    slots = sorted(seats)
    for start in range(len(slots) - span + 1):
        run = tuple(slots[start : start + span])
        if run[-1] - run[0] != span - 1:
            continue
        if _within(seat_pose(seats, run), X, t.seat_xy, t.seat_z, t.seat_tilt, t.seat_yaw):
            names = tuple(f"slot_{k}" for k in run)
            return PartPlacement(
                PartStatus.SEATED, seats=names, slots=run, token=g.token(part, run, None)
            )
    return None


def _host_seat(g: SeatGeometry, t, part, poses, seats, base) -> PartPlacement | None:
    if g.spans[part] != 1:
        return None
    for host, rows in g.hosts:
        if host == part:
            continue
        for row, X_HR in rows:
            X_W_seat = poses[host] @ X_HR
            if not _within(X_W_seat, poses[part], t.host_xy, t.host_z, t.host_tilt, t.host_yaw):
                continue
            slots: tuple[int, ...] = ()
            token = None
            if host in base:  # the base slot under this row: the host may sit either way round
                for k, X_W_slot in seats.items():
                    d = np.linalg.norm((X_W_seat.translation() - X_W_slot.translation())[:2])
                    if d <= t.host_over_slot:
                        slots = (k,)
                        token = g.token(part, slots, host)
            return PartPlacement(
                PartStatus.SEATED, seats=(row,), slots=slots, host=host, token=token
            )
    return None


def _held(g: SeatGeometry, t: CameraTolerances, part, X, X_W_tcp) -> bool:
    if X_W_tcp is None or part not in g.grasps:
        return False
    distance, angle = rotation_angle(X_W_tcp, X @ g.grasps[part])
    if distance > t.held_position:
        return False
    # The flanges are symmetric under a half turn about the approach axis.
    return angle <= t.held_angle or abs(angle - math.pi) <= t.held_angle


def _resting_on(X_W_body, frames, end, half_width, X, t: CameraTolerances) -> bool:
    """Whether X lies on the surface whose seat frames (in its body) are `frames`: over it
    (its length `end` past the outer seats, `half_width` across, REST_MARGIN more) and within
    the band a part resting on it lies in."""
    p = X_W_body.InvertAndCompose(X).translation()
    centres = np.array([X_BS.translation() for X_BS in frames])
    x, y, z = p[0], p[1] - centres[:, 1].mean(), p[2] - centres[:, 2].mean()
    return (
        centres[:, 0].min() - end - REST_MARGIN <= x <= centres[:, 0].max() + end + REST_MARGIN
        and abs(y) <= half_width + REST_MARGIN
        and -t.rest_below <= z <= REST_ABOVE
    )


def _misplaced(g: SeatGeometry, t, part, poses, X_W_plate) -> bool:
    X = poses[part]
    if _resting_on(X_W_plate, [X for _, X in g.slots], PLATE_END, PLATE_WIDTH / 2, X, t):
        return True
    return any(
        host != part
        and _resting_on(poses[host], [X for _, X in rows], HOST_END, HOST_WIDTH / 2, X, t)
        for host, rows in g.hosts
    )


def _in_tray(g: SeatGeometry, t: CameraTolerances, part, X) -> bool:
    for symbol, X_WH in g.homes:
        if symbol != g.symbols[part]:
            continue
        xy, z, tilt, yaw = pose_error(X_WH, X)
        if math.hypot(xy, z) <= t.tray_position and max(tilt, yaw) <= t.tray_angle:
            return True
    return False


def frame_placements(
    g: SeatGeometry,
    t: CameraTolerances,
    poses: Mapping[str, RigidTransform],
    X_W_plate: RigidTransform,
    X_W_tcp: RigidTransform | None,
    lifted: frozenset[str] = frozenset(),
) -> dict[str, PartPlacement]:
    """One frame's verdict on every part (no poses in the placements), from the parts'
    estimated world `poses`, the plate's pose and the tcp's (None: no robot); the module
    docstring says how. The parts `lifted` are read in no seat (they do not rest on its floor:
    `hrc_drake.cell.station.camera_rest`)."""
    seats = {k: X_W_plate @ X_PS for k, X_PS in g.slots}
    placed: dict[str, PartPlacement] = {}
    for part in sorted(poses):
        found = None if part in lifted else _base_seat(g, t, part, poses[part], seats)
        if found is not None:
            placed[part] = found
    base = dict(placed)
    for part in sorted(poses):
        if part in placed:
            continue
        found = None if part in lifted else _host_seat(g, t, part, poses, seats, base)
        if found is not None:
            placed[part] = found
        elif _held(g, t, part, poses[part], X_W_tcp):
            placed[part] = PartPlacement(PartStatus.HELD)
        elif _misplaced(g, t, part, poses, X_W_plate):
            placed[part] = PartPlacement(PartStatus.MISPLACED)
        elif _in_tray(g, t, part, poses[part]):
            placed[part] = PartPlacement(PartStatus.TRAY)
        else:
            placed[part] = PartPlacement(PartStatus.TRANSIT)
    return placed


def label(placement: PartPlacement) -> tuple[str, tuple[str, ...], str, str]:
    """What a verdict says, its pose aside: (status, seats, host, token)."""
    p = placement
    return (p.status.value, p.seats, p.host or "", p.token or "")


@dataclass(frozen=True)
class Verdict:
    """One part's verdict as the camera reports it: `reported`, and the `candidate` the
    latest frames agree on, seen in `run` frames in a row."""

    reported: PartPlacement
    candidate: PartPlacement
    run: int

    @property
    def steady(self) -> bool:
        """Whether the latest frame agrees with the verdict reported (a tentative one, `run`
        0, tells nothing yet: a part that moved is read again before the reading holds)."""
        return self.run > 0 and label(self.candidate) == label(self.reported)


def follow(
    previous: Verdict | None,
    seen: PartPlacement,
    frames: int = CONFIRM_FRAMES,
    tentative: bool = False,
) -> Verdict:
    """The verdict after a frame that sees `seen`: it changes once `frames` frames in a row
    agree on a new one. The first frame is taken as confirmed (the camera ran before). A
    `tentative` frame (a seat the still part's frames cannot yet confirm) counts toward no
    change and is not steady."""
    seen = replace(seen, pose=())
    if previous is None:
        return Verdict(seen, seen, frames)
    if tentative:
        return Verdict(previous.reported, seen, 0)
    run = previous.run + 1 if label(seen) == label(previous.candidate) else 1
    reported = seen if run >= frames else previous.reported
    return Verdict(reported, seen, run)


__all__ = [
    "CONFIRM_FRAMES",
    "K_SIGMA",
    "REST_ABOVE",
    "CameraTolerances",
    "Verdict",
    "check_camera_noise",
    "follow",
    "frame_placements",
    "label",
    "max_noise",
    "radial_quantile",
]
