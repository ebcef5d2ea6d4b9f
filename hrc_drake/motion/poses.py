"""Grasp and place poses, derived from the models' frames and the assembly spec.

This is the one pose rule of the project (docs/conventions.md): the spec says what a token
places (`AssemblySpec.placement`), and
- a part on the base over slots k..m sits at the mean of the seat frames `slot_k`..`slot_m`
  (they share their orientation);
- a part on a host over base slot k sits on the host's row over k: `X_W_host · X_host_row_j`,
  j = the position of k among the slots the host covers (`row_1` over the lowest);
- the gripper's pads hold a part with their centre at its `grasp` frame; the pads travel along
  the approach axis with the opening (`hrc_drake.rg2_kinematics`), so the `tcp` (the pads'
  centre at a 45 mm opening) stands where `tcp_in_part` says for the width the grasp closes on.
The cell station (initial poses, bolt welds), the motion layer and the SlotMonitor's nominal
seats all use these functions.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform

from hrc_drake.cell_models import CellDesign
from hrc_drake.rg2_kinematics import pad_offset
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.tokens import UNDO, Placement


def seat_pose(seats: Mapping[int, RigidTransform], slots: Iterable[int]) -> RigidTransform:
    """The pose of a part covering base `slots`, given the seat frames of the slots (in any one
    frame): the mean of their positions, with their (common) orientation."""
    slots = tuple(slots)
    missing = [k for k in slots if k not in seats]
    if missing:
        raise ValueError(
            f"base slot {missing[0]} has no seat frame slot_{missing[0]} (the plate has "
            f"{len(seats)} slots)"
        )
    position = np.mean([seats[k].translation() for k in slots], axis=0)
    return RigidTransform(seats[slots[0]].rotation(), position)


def host_row(host: Placement, slot: int) -> int:
    """The row (from 1) of a host placed as `host` that sits over base `slot`."""
    if slot not in host.slots:
        raise ValueError(f"the host {host.part} placed over {list(host.slots)} is not over {slot}")
    return host.slots.index(slot) + 1


@dataclass(frozen=True)
class CellFrames:
    """World poses of the seats and tray homes, and each part's fixed frames.

    Attributes:
        design: the cell (spec, layout, part instances).
        seats: base slot k -> X_W_slot_k.
        homes: part instance -> X_W_part at rest in the tray (`home_<instance>`).
        rows: host part symbol -> row j -> X_host_row_j.
        grasps: part instance -> X_part_tcp, the gripper's tcp in the part's frame when it holds
            the part: `tcp_in_part` of the part's `grasp` frame at its width (a cell read
            without the gripper: the `grasp` frame itself).
        widths: part instance -> width between the fingers when held [m].
        tray: X_W_tray, the tray's body frame.
    """

    design: CellDesign
    seats: Mapping[int, RigidTransform]
    homes: Mapping[str, RigidTransform]
    rows: Mapping[str, Mapping[int, RigidTransform]]
    grasps: Mapping[str, RigidTransform]
    widths: Mapping[str, float]
    tray: RigidTransform = field(default_factory=RigidTransform)

    @property
    def spec(self) -> AssemblySpec:
        """The assembly spec of the cell."""
        return self.design.spec

    def with_seat(self, slot: int, X_W_slot: RigidTransform) -> CellFrames:
        """A copy with base slot `slot` moved to `X_W_slot` (tests: an unreachable seat)."""
        return replace(self, seats={**self.seats, slot: X_W_slot})


def part_pose(frames: CellFrames, token: str, configuration: Iterable[str]) -> RigidTransform:
    """X_W_part of the part placed at `token`, given the tokens in place (`configuration`).

    A part on a host needs its host's token in `configuration`.
    """
    spec = frames.spec
    placement = spec.placement(token)
    if placement.host is None:
        try:
            return seat_pose(frames.seats, placement.slots)
        except ValueError as err:
            raise ValueError(f"{token}: {err}") from err
    (slot,) = placement.slots
    hosts = [
        (t, p)
        for t, p in ((t, spec.placement(t)) for t in configuration)
        if p.part == placement.host and p.host is None and slot in p.slots
    ]
    if len(hosts) != 1:
        raise ValueError(
            f"{token} needs one {placement.host} over base slot {slot} among "
            f"{sorted(configuration)}"
        )
    host_token, host = hosts[0]
    X_W_host = part_pose(frames, host_token, configuration)
    return X_W_host @ frames.rows[host.part][host_row(host, slot)]


# The placement of a part at its home in the tray (in layouts and scenario placements).
IN_TRAY = "tray"


def layout_poses(frames: CellFrames, layout: Mapping[str, str]) -> dict[str, RigidTransform]:
    """World poses of part instances placed as `layout` says (instance -> token or `IN_TRAY`)."""
    configuration = [t for t in layout.values() if t != IN_TRAY]
    poses = {}
    for instance, token in layout.items():
        if instance not in frames.homes:
            raise ValueError(
                f"{instance!r} is not a part of the cell; parts are {', '.join(frames.homes)}"
            )
        if token == IN_TRAY:
            poses[instance] = frames.homes[instance]
            continue
        symbol = frames.design.symbol_of(instance)
        if frames.spec.placement(token).part != symbol:
            raise ValueError(f"token {token!r} does not place {instance} (a {symbol})")
        poses[instance] = part_pose(frames, token, configuration)
    return poses


def default_layout(
    frames: CellFrames, configuration: Iterable[str], last_token: str | None = None
) -> dict[str, str]:
    """Which instance would sit at each token if the robot alone had built `configuration`.

    The robot takes parts from the tray lowest-numbered first and undoes last in, first out, so
    among the tokens of one symbol the one placed last (`last_token`) holds the highest-numbered
    instance; the others go base tokens first, then by token. For planning without a cell (cost
    tables, benchmarks); in the cell, the SlotMonitor measures the layout instead.
    Returns instance -> token.
    """
    spec = frames.spec
    tokens = sorted(configuration)
    layout: dict[str, str] = {}
    for part in spec.parts:
        instances = frames.design.instances_of(part.symbol)
        mine = [t for t in tokens if spec.placement(t).part == part.symbol]
        mine.sort(key=lambda t: (t == last_token, spec.placement(t).host is not None, t))
        if len(mine) > len(instances):
            raise ValueError(f"configuration {tokens} holds more {part.symbol} than {instances}")
        layout.update(dict(zip(instances, mine, strict=False)))
    return layout


def tcp_in_part(X_part_grasp: RigidTransform, opening: float) -> RigidTransform:
    """X_part_tcp: where the gripper's `tcp` stands, in a part's frame, when its pads hold the
    part with their centre at its `grasp` frame and the fingers `opening` [m] apart.

    The one tcp rule of the project. The RG2's pads swing back toward the flange as they open
    (`hrc_drake.rg2_kinematics.pad_offset`, 0 at the tcp's own 45 mm), so for a wider part the
    tcp, fixed on the gripper, goes further along its approach axis (+z): 16.3 mm at 90 mm."""
    return X_part_grasp @ RigidTransform([0.0, 0.0, -pad_offset(opening)])


def tcp_pose(frames: CellFrames, instance: str, X_W_part: RigidTransform) -> RigidTransform:
    """X_W_tcp when holding `instance` at X_W_part (`CellFrames.grasps`: its pads at the part's
    `grasp` frame, closed on its width)."""
    return X_W_part @ frames.grasps[instance]


def offset_along_approach(X_W_tcp: RigidTransform, distance: float) -> RigidTransform:
    """X_W_tcp moved back `distance` against its approach axis (+z of tcp): pre-grasp, retreat."""
    z = X_W_tcp.rotation().col(2)
    return RigidTransform(X_W_tcp.rotation(), X_W_tcp.translation() - distance * np.asarray(z))


# Measured poses and postures as plan-cache keys: translations to 0.1 mm, quaternion
# components and joint angles to 1e-4 (about 0.2 mrad). A plan is made from the rounded values,
# so that a plan is a function of its cache key (same request, same plan, in any process).
KEY_DIGITS = 4


def pose_values(X: RigidTransform) -> tuple[float, ...]:
    """The 7 values (x, y, z, qw, qx, qy, qz) of a pose: its translation, then the quaternion
    `RotationMatrix.ToQuaternion()` gives."""
    q = X.rotation().ToQuaternion()
    return (*(float(v) for v in X.translation()), q.w(), q.x(), q.y(), q.z())


def pose_from_values(values: Sequence[float]) -> RigidTransform:
    """The pose of 7 values (x, y, z, qw, qx, qy, qz); the quaternion is normalized."""
    values = _finite(values, 7, "a pose (x, y, z, qw, qx, qy, qz)")
    q = np.array(values[3:])
    norm = float(np.linalg.norm(q))
    if norm < 0.5:
        raise ValueError(f"pose {values}: its quaternion (qw, qx, qy, qz) is not a rotation")
    return RigidTransform(Quaternion(q / norm), np.array(values[:3]))


def quantize_pose(values: Sequence[float]) -> tuple[float, ...]:
    """A pose's 7 values rounded to the plan cache's resolution (`KEY_DIGITS`), with the
    quaternion normalized and its sign fixed (qw >= 0), so that one rotation has one key."""
    values = pose_values(pose_from_values(values))
    sign = -1.0 if values[3] < 0.0 else 1.0
    rounded = [*values[:3], *(sign * v for v in values[3:])]
    return tuple(round(v, KEY_DIGITS) + 0.0 for v in rounded)  # + 0.0: no -0.0


def quantize_joints(values: Sequence[float], count: int = 6) -> tuple[float, ...]:
    """Joint positions [rad] rounded to the plan cache's resolution (`KEY_DIGITS`)."""
    values = _finite(values, count, f"a posture ({count} joint positions)")
    return tuple(round(v, KEY_DIGITS) + 0.0 for v in values)


def quantize_opening(opening: float) -> float:
    """A gripper opening [m] rounded to the plan cache's resolution (0.1 mm, `KEY_DIGITS`)."""
    value = _finite((opening,), 1, "a gripper opening")[0]
    return round(value, KEY_DIGITS) + 0.0


def _finite(values: Sequence[float], count: int, what: str) -> tuple[float, ...]:
    values = tuple(float(v) for v in np.asarray(values, dtype=float).ravel())
    if len(values) != count or not all(np.isfinite(values)):
        raise ValueError(f"{what} needs {count} finite numbers, got {values}")
    return values


__all__ = [
    "KEY_DIGITS",
    "UNDO",
    "CellFrames",
    "default_layout",
    "host_row",
    "layout_poses",
    "offset_along_approach",
    "part_pose",
    "pose_from_values",
    "pose_values",
    "quantize_joints",
    "quantize_opening",
    "quantize_pose",
    "seat_pose",
    "tcp_in_part",
    "tcp_pose",
]
