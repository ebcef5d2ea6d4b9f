"""The person model both sides of the cell share: the operator's body as capsules and spheres
(arm lengths and radii of an adult, the elbow by two-link inverse kinematics, the torso leaning
in when the arm is too short), the body as spheres over time (`body_samples`, what a tracker
reports and what a forecast predicts) and the desk as the person sees it (`desk_of`: the bins,
and the seat of every placement). The station's `OperatorBody` and `DeskScript` move the
simulated person by it; the controller's `OperatorForecast` predicts the person by it."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hrc_drake.hri.activity import SHOULDER, Desk, DeskBin, HandTimeline, Person
from hrc_drake.layout import CellLayout
from hrc_drake.motion.clearance import Occupancy
from hrc_drake.motion.poses import CellFrames

UPPER_ARM, FOREARM = 0.30, 0.32  # shoulder-elbow, elbow-hand centre [m] (adult, ~50th pct)
ARM_RADII = (0.045, 0.04)
HAND_RADIUS = 0.05
TORSO_RADIUS, TORSO_LENGTH = 0.15, 0.45
HEAD_RADIUS = 0.10
TORSO_CENTRE = np.array([0.0, 0.0, 0.25])
HEAD_CENTRE = np.array([0.0, 0.0, 0.75])
CHAIN_GAP = 1 - np.sqrt(3) / 2  # of a chain sphere's radius (see `_chain_steps`)


def elbow(shoulder: np.ndarray, hand: np.ndarray, left: bool = False) -> np.ndarray:
    """The elbow of a two-link arm from `shoulder` to `hand` (elbow down and outward)."""
    d_vec = hand - shoulder
    d = float(np.clip(np.linalg.norm(d_vec), 1e-6, UPPER_ARM + FOREARM - 1e-6))
    u = d_vec / max(np.linalg.norm(d_vec), 1e-9)
    a = (UPPER_ARM**2 - FOREARM**2 + d**2) / (2 * d)
    h = np.sqrt(max(UPPER_ARM**2 - a**2, 0.0))
    pole = np.array([0.0, -0.4 if left else 0.4, -1.0])
    w = pole - pole.dot(u) * u
    w /= max(np.linalg.norm(w), 1e-9)
    return shoulder + a * u + h * w


def _chain_steps(radius: float, length: float) -> np.ndarray:
    """Where the spheres of a capsule of nominal `length` sit along it (0 to 1), spaced ≤ the
    radius (a fixed count per capsule): their union misses the capsule's surface by at most
    (1 − √3/2) × radius between two spheres (`CHAIN_GAP`), which the monitor subtracts."""
    return np.linspace(0.0, 1.0, int(np.ceil(1.1 * length / radius)) + 1)[:, None]


# The body's parts as sphere chains: (steps along the part, radius); computed once.
_FOREARM_STEPS = _chain_steps(ARM_RADII[1], FOREARM)
_UPPER_ARM_STEPS = _chain_steps(ARM_RADII[0], UPPER_ARM)
_TORSO_STEPS = _chain_steps(TORSO_RADIUS, TORSO_LENGTH)
_COUNTS = (1, len(_FOREARM_STEPS), len(_UPPER_ARM_STEPS), len(_TORSO_STEPS), 1)
_RADII = np.concatenate(
    [
        np.full(n, r)
        for n, r in zip(
            _COUNTS, (HAND_RADIUS, *ARM_RADII[::-1], TORSO_RADIUS, HEAD_RADIUS), strict=True
        )
    ]
)
_ENDS = np.cumsum(_COUNTS)
_GROUPS = tuple((int(e - n), int(e)) for e, n in zip(_ENDS, _COUNTS, strict=True))
_HALF_TORSO = np.array([0.0, 0.0, TORSO_LENGTH / 2])


@dataclass(frozen=True)
class BodyPose:
    """Key points of the body in world [m]."""

    def __deepcopy__(self, memo) -> BodyPose:
        return self  # immutable once made

    shoulder: np.ndarray
    elbow: np.ndarray
    hand: np.ndarray
    torso: np.ndarray
    head: np.ndarray

    def spheres(self) -> tuple[np.ndarray, np.ndarray, tuple[tuple[int, int], ...]]:
        """(centres n×3, radii n, index ranges of the parts) of the body as spheres: the hand,
        the forearm, the upper arm, the torso, the head."""
        bottom = self.torso - _HALF_TORSO
        centres = np.vstack(
            [
                self.hand,
                self.elbow + _FOREARM_STEPS * (self.hand - self.elbow),
                self.shoulder + _UPPER_ARM_STEPS * (self.elbow - self.shoulder),
                bottom + _TORSO_STEPS * (2 * _HALF_TORSO),
                self.head,
            ]
        )
        return centres, _RADII, _GROUPS


def body_pose(stance: np.ndarray, hand: np.ndarray, left: bool = False) -> BodyPose:
    """The body standing at `stance` (x, y) with the hand centre at `hand` (of the left arm
    with `left`); the torso leans toward the hand when the arm is too short."""
    base = np.array([stance[0], stance[1], 0.0])
    shoulder = base + SHOULDER * [1.0, -1.0 if left else 1.0, 1.0]
    reach = np.linalg.norm(hand - shoulder)
    limit = 0.97 * (UPPER_ARM + FOREARM)
    lean = np.zeros(3)
    if reach > limit:
        # Lean horizontally toward the hand until the arm reaches it.
        d = hand - shoulder
        horizontal = float(np.hypot(d[0], d[1]))
        needed = np.sqrt(max(limit**2 - min(d[2] ** 2, limit**2), 0.0))
        lean[:2] = d[:2] / max(horizontal, 1e-9) * max(horizontal - needed, 0.0)
    shoulder = shoulder + lean
    return BodyPose(
        shoulder=shoulder,
        elbow=elbow(shoulder, hand, left),
        hand=hand,
        torso=base + TORSO_CENTRE + lean,
        head=base + HEAD_CENTRE + lean,
    )


HOSTED_ABOVE = 0.02  # m: a seat on a host part stands about this far above the base's


def desk_of(frames: CellFrames, layout: CellLayout) -> Desk:
    """The desk of a cell: the layout's bins, and where each placement token's seat is."""
    spec = frames.spec
    seats, parts = {}, {}
    for token, mount, slots in spec.placements():
        centre = np.mean([frames.seats[k].translation() for k in slots], axis=0)
        if spec.placement(token).host is not None:
            centre = centre + np.array([0.0, 0.0, HOSTED_ABOVE])
        seats[token] = tuple(float(x) for x in centre)
        parts[token] = mount.part
    bins = tuple(DeskBin(b.name, b.holds, b.grab_point()) for b in layout.bins)
    bolts = {p.symbol: p.bolt_count for p in spec.parts}
    return Desk(bins, seats, parts, bolts)


@functools.lru_cache(maxsize=4096)
def _sphere_centres(stance: tuple, hand: tuple, left: bool) -> np.ndarray:
    """The centres of `BodyPose.spheres` for `body_pose(stance, hand, left)`, kept for the
    hand places met again: a forecast's timelines hold the hand at rest in the same place on
    many samples (read-only: shared between the calls)."""
    centres = body_pose(np.array(stance), np.array(hand), left).spheres()[0]
    centres.flags.writeable = False
    return centres


def body_samples(person: Person, timeline: HandTimeline, times: np.ndarray) -> Occupancy:
    """The body as spheres at `times` with the hand on `timeline` (velocities by differences,
    as a tracker reports them)."""
    stance = tuple(float(x) for x in person.stance)
    centres = np.array(
        [_sphere_centres(stance, tuple(timeline.at(t)), person.left_handed) for t in times]
    )
    velocities = np.zeros_like(centres)
    if len(times) > 1:
        velocities = np.gradient(centres, times, axis=0)
    return Occupancy(np.asarray(times, dtype=float), centres, _RADII, velocities)


# Every whole body's spheres (`BodyPose.spheres`): their radii and the parts' index ranges.
BODY_RADII, BODY_GROUPS = _RADII, _GROUPS
# The hand, forearm and upper arm: the first three groups of `BodyPose.spheres`.
ARM_SPHERES = body_pose(np.zeros(2), np.array([0.5, 0.0, 0.1])).spheres()[2][2][1]


__all__ = [
    "ARM_SPHERES",
    "BODY_GROUPS",
    "BODY_RADII",
    "CHAIN_GAP",
    "BodyPose",
    "body_pose",
    "body_samples",
    "desk_of",
    "elbow",
]
