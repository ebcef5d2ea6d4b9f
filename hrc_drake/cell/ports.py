"""The values on the ports between the station and the controller that both sides build or
read: where every part is (`CellConfiguration`, the configuration sensor's reading), the
operator's body as a tracker reports it (`BodySpheres`) and the simulated operator's activity
(`OperatorActivity`, which the station's body and desk scripts key on). They live here, apart
from the systems that make them, so that the controller needs nothing of the simulated station
(`hrc_drake.cell.station.build`) to read them, and the LCM link (`hrc_drake.cell.link`) encodes them
without either side."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix


class PartStatus(enum.Enum):
    """Where a part is, as the SlotMonitor sees it."""

    SEATED = "seated"  # in a seat of the plate or of a host part
    HELD = "held"  # in the gripper, in no seat
    MISPLACED = "misplaced"  # on the plate or a host part, in no seat
    TRAY = "tray"  # at rest at a tray home frame
    TRANSIT = "transit"  # anywhere else (moving, or lying elsewhere)


@dataclass(frozen=True)
class PartPlacement:
    """One part's placement. `slots` are the base slots under it (empty unless seated).

    `pose` is the part body's measured world pose `(x, y, z, qw, qx, qy, qz)` (m, then the unit
    quaternion), filled by the SlotMonitor for every part in every status; empty for a
    placement built without one. It is read to the last bit, so it jitters between steps while
    the status and token stand still: to tell whether the cell changed, compare
    `CellConfiguration.tokens()` or the statuses, not whole configurations. Use
    `placement_transform` for it as a RigidTransform.
    """

    status: PartStatus
    seats: tuple[str, ...] = ()  # seat frames it sits in, e.g. ("slot_1", "slot_2") or ("row_2",)
    slots: tuple[int, ...] = ()
    host: str | None = None  # model instance of the host part, for a part on another part
    token: str | None = None  # task token, e.g. "F3", "S12", "F01"; None unless seated in place
    pose: tuple[float, ...] = ()  # world pose: x, y, z [m], qw, qx, qy, qz; () if not measured


def pose_tuple(X: RigidTransform) -> tuple[float, ...]:
    """`X` as `PartPlacement.pose`: (x, y, z, qw, qx, qy, qz), the translation and
    `RotationMatrix.ToQuaternion()`."""
    q = X.rotation().ToQuaternion()
    x, y, z = (float(v) for v in X.translation())
    return (x, y, z, float(q.w()), float(q.x()), float(q.y()), float(q.z()))


def placement_transform(placement: PartPlacement) -> RigidTransform:
    """The world pose of a placement as a RigidTransform; ValueError if it has none (or not a
    7-float pose with a non-zero finite quaternion)."""
    pose = placement.pose
    if not pose:
        raise ValueError(
            f"a {placement.status.value} placement without a pose: only the SlotMonitor's "
            "placements (or a configuration message with has_pose) carry one"
        )
    if len(pose) != 7:
        raise ValueError(
            f"a placement pose of {len(pose)} values; it must be 7: x, y, z, qw, qx, qy, qz"
        )
    q = np.asarray(pose[3:], dtype=float)
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 0.0) or not np.all(np.isfinite(pose[:3])):
        raise ValueError(f"a placement pose {pose} that is not finite, or has a zero quaternion")
    # Quaternion() refuses what is not unit length to within its tolerance: a pose read from
    # elsewhere (a camera) may be off by more than that.
    return RigidTransform(RotationMatrix(Quaternion(q / norm)), np.asarray(pose[:3], dtype=float))


@dataclass(frozen=True)
class CellConfiguration:
    """The placement of every part, sorted by model instance name. Two readings are equal only
    if every pose is, to the bit: to see whether the cell changed, compare `tokens()` (or the
    statuses)."""

    placements: tuple[tuple[str, PartPlacement], ...] = ()
    # The world pose (x, y, z, qw, qx, qy, qz) of a temporary obstacle seen in the work
    # (`hrc_drake.obstacle_models`), or () when there is none.
    obstacle: tuple[float, ...] = ()
    # Up to when the verdicts are known to hold [s, station time]: a camera's newest frame
    # whose every part's view agreed with the verdict reported (`hrc_drake.cell.station.camera`).
    # None: now (the contact sensor, exact at every step, or a reading over the lockstep link,
    # whose message carries the exchange's time; the real-time link carries it and restamps it,
    # `hrc_drake.cell.link.realtime`).
    stamp: float | None = None

    def __deepcopy__(self, memo) -> CellConfiguration:
        # Immutable: Drake's copies of this abstract value can share it.
        return self

    def placement(self, instance: str) -> PartPlacement:
        """The placement of the part `instance`; KeyError naming the known parts if unknown."""
        for name, placement in self.placements:
            if name == instance:
                return placement
        known = ", ".join(name for name, _ in self.placements)
        raise KeyError(f"no part {instance!r} in the cell configuration (parts: {known})")

    def status(self, instance: str) -> PartStatus:
        """The status of the part `instance`."""
        return self.placement(instance).status

    def tokens(self) -> frozenset[str]:
        """The task-layer configuration: the tokens of the seated parts, e.g. {"F3","S12","F01"}."""
        return frozenset(p.token for _, p in self.placements if p.token is not None)

    def layout(self) -> dict[str, str]:
        """Which part instance sits at each token: instance -> token, seated parts only."""
        return {name: p.token for name, p in self.placements if p.token is not None}

    def held(self) -> str | None:
        """The part read as in the gripper (None: none)."""
        return next((name for name, p in self.placements if p.status == PartStatus.HELD), None)

    def current_at(self, time: float) -> bool:
        """Whether the reading's verdicts hold at `time` or later: what a reader waits for
        before it believes what the cell shows after `time` (a part let go, come to rest)."""
        return self.stamp is None or self.stamp >= time - 1e-9


@dataclass(frozen=True)
class BodySpheres:
    """The body as world-frame spheres: centres (n×3) [m], radii (n) [m], velocities (n×3)
    [m/s]; `groups` are the index ranges [start, end) of the body's parts (hand, forearm, upper
    arm, torso, head), each part within the sphere `bound(group)`. `stamp` is when the tracker
    took this reading [s, station time], set by a sensor model (`sensors:`); None: now (an
    exact tracker, or a reading over the lockstep link, whose message carries the exchange's
    time; the real-time link carries it, `hrc_drake.cell.link.realtime`). `lost_for` is set by
    the controller only: the seconds since the person was last seen, for a body it remembers and
    grows while the tracker sees nobody (`hrc_drake.cell.controller.body_memory`); None for a
    reading."""

    centres: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray
    groups: tuple[tuple[int, int], ...] = ()
    stamp: float | None = None
    lost_for: float | None = None

    def bound(self, group: int) -> tuple[np.ndarray, float]:
        """(centre, radius) of a sphere that holds every sphere of `group`."""
        start, end = self.groups[group]
        a, b = self.centres[start], self.centres[end - 1]
        centre = (a + b) / 2
        return centre, float(np.linalg.norm(b - a) / 2 + self.radii[start:end].max())

    def __deepcopy__(self, memo) -> BodySpheres:
        return self  # immutable once made (Drake copies abstract values often)


# Nobody tracked: what the body tracker reports with no one in the cell (and an unconnected
# body input reads).
NOBODY = BodySpheres(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))


class SafetyMode(enum.IntEnum):
    """The robot's safety mode as its safety system reports it (`safety.mode`), with the codes
    of UR's RTDE `safety_mode` (Universal Robots' client library and RTDE guide: 1 normal,
    2 reduced, 3 protective stop, 5 safeguard stop)."""

    NORMAL = 1  # full limits
    REDUCED = 2  # a person within the reduced band: the safety function may stop the arm soon
    PROTECTIVE_STOP = 3  # stopped until the cause clears and someone unlocks
    SAFEGUARD_STOP = 5  # stopped until the separation clears, then resumes by itself

    @property
    def stopped(self) -> bool:
        """Whether the safety system holds the arm still."""
        return self in (SafetyMode.PROTECTIVE_STOP, SafetyMode.SAFEGUARD_STOP)


class ActivityKind(StrEnum):
    """What the simulated operator is doing."""

    REST = "rest"
    BOLT = "bolt"


@dataclass(frozen=True)
class OperatorActivity:
    """The simulated operator's activity: `kind` on `part` from `start` for `duration` seconds
    (decision `step`); `answered_step`, `answered_at` and `answered_task` say when the operator
    last indicated a task, and which (body motions key on it)."""

    kind: ActivityKind = ActivityKind.REST
    part: str = ""
    start: float = 0.0
    duration: float = 0.0
    step: int = 0
    answered_step: int = 0
    answered_at: float = float("-inf")
    answered_task: str = ""

    def __deepcopy__(self, memo) -> OperatorActivity:
        return self  # immutable


__all__ = [
    "NOBODY",
    "ActivityKind",
    "BodySpheres",
    "CellConfiguration",
    "OperatorActivity",
    "PartPlacement",
    "PartStatus",
    "placement_transform",
    "pose_tuple",
]
