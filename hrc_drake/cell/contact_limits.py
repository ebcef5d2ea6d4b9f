"""Power and force limiting's judgement of a contact (ISO/TS 15066:2016 §5.5.5, Annex A), stated
once for the three that ask it: the station's safety function and the controller's monitor (how
fast the arm may approach a body region inside S_p) and the run's own check (whether it did).

Each part of the person model (`hrc_drake.cell.person.BodyPose.spheres`: hand, forearm, upper
arm, torso, head) is one of Annex A's body regions (`REGIONS`). A transient contact of the
robot, effective mass m_R along the direction of approach, with a region of effective mass m_H
and spring constant k stays within the region's permissible force F when the relative speed is
at most

    v_max = F / √(μ k),   μ = (1/m_H + 1/m_R)⁻¹   (Annex A's energy-transfer model)

with F twice the quasi-static limit for a transient contact, the quasi-static limit itself where
the region could be clamped (`clamped`: over the table, pushed down toward it within
`CLAMP_REACH`): there the impact's peak may not exceed what the region bears held, and the force
a stopped robot then holds is its own force limit's, not judged here. The force a speed v
implies is F = v √(μ k). The head permits none. m_R comes from the robot's
model at the pose (`hrc_drake.cell.effective_mass`); where it is not at hand (the safety function
and the monitor, every step) m_R → ∞ bounds it from below: μ = m_H, a speed the region permits
at any pose (`least_permissible_speeds`).

The speed judged is the robot's toward the region: the person's own motion is not the robot's to
limit, and Annex A's relative speed with the region at rest is how power and force limiting robots
are set.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell_models import TABLE_HALF, TABLE_POSITION


@dataclass(frozen=True)
class BodyRegion:
    """One of Annex A's body regions: its quasi-static force limit [N] (a transient contact
    permits `TRANSIENT_FACTOR` times it), effective spring constant [N/m] and effective mass
    [kg]; `touchable` False: no contact permitted (the skull and face)."""

    name: str
    quasi_static_force: float
    stiffness: float
    mass: float
    touchable: bool = True

    def force_limit(self, clamped) -> np.ndarray:
        """The permissible force [N]: quasi-static where `clamped`, else transient."""
        return np.where(clamped, 1.0, TRANSIENT_FACTOR) * self.quasi_static_force


# ISO/TS 15066:2016 Annex A, Table A.2 (quasi-static force) and Table A.3 (effective spring
# constant, effective mass), third-party transcriptions; the hand, lower and upper arm rows in
# shared/reference/collaboration.md. The torso is judged as the chest, the most cautious of its
# regions (back and shoulders, chest, abdomen, pelvis) at m_R → ∞: 0.28 m/s transient.
TRANSIENT_FACTOR = 2.0
HAND = BodyRegion("hand", 140.0, 75e3, 0.6)
LOWER_ARM = BodyRegion("lower arm", 160.0, 40e3, 2.0)
UPPER_ARM = BodyRegion("upper arm", 150.0, 30e3, 3.0)
CHEST = BodyRegion("chest", 140.0, 25e3, 40.0)
SKULL = BodyRegion("skull and forehead", 130.0, 150e3, 4.4, touchable=False)
# The regions of the person model's parts, in `BodyPose.spheres`'s order.
REGIONS = (HAND, LOWER_ARM, UPPER_ARM, CHEST, SKULL)
# A region can be clamped when its sphere's centre lies over the table, its lowest point within
# this of the table's top, and the robot pushes it down (our choice: the plate, its parts and a
# resting hand stand under 0.1 m; a sideways push lets the hand slide, a push more than 30° below
# the horizontal pins it).
CLAMP_REACH = 0.10  # m
CLAMP_SLOPE = -0.5  # the approach direction's z at most this (sin 30° down)


@functools.lru_cache(maxsize=8)
def _region_rows(groups: tuple[tuple[int, int], ...], n: int) -> np.ndarray:
    rows = np.zeros(n, dtype=int)  # a body without the parts (a test's probe): all hand
    if len(groups) == len(REGIONS):
        for row, (start, end) in enumerate(groups):
            rows[start:end] = row
    rows.flags.writeable = False
    return rows


def region_rows(body: BodySpheres) -> np.ndarray:
    """Per sphere of `body`, its region's row in `REGIONS`; a body without the person model's
    parts (a test's lone probe) is hand throughout."""
    return _region_rows(tuple(body.groups), len(body.radii))


@functools.lru_cache(maxsize=8)
def _least_speeds(groups: tuple[tuple[int, int], ...], n: int) -> np.ndarray:
    speeds = np.array(
        [
            r.force_limit(False) / np.sqrt(r.mass * r.stiffness) if r.touchable else 0.0
            for r in REGIONS
        ]
    )[_region_rows(groups, n)]
    speeds.flags.writeable = False
    return speeds


@functools.lru_cache(maxsize=8)
def _touchable(groups: tuple[tuple[int, int], ...], n: int) -> np.ndarray:
    mask = np.array([r.touchable for r in REGIONS])[_region_rows(groups, n)]
    mask.flags.writeable = False
    return mask


def touchable(body: BodySpheres) -> np.ndarray:
    """Per sphere of `body`, whether power and force limiting permits a contact there: all but
    the head, as Annex A permits none with the face or skull. A body without the parts (a
    test's lone sphere) is all touchable."""
    return _touchable(tuple(body.groups), len(body.radii))


def least_permissible_speeds(body: BodySpheres) -> np.ndarray:
    """Per sphere of `body`, the speed [m/s] a transient contact of its region permits against
    a robot of any effective mass (m_R → ∞: μ = m_H); 0 at the head."""
    return _least_speeds(tuple(body.groups), len(body.radii))


def least_speeds_at(body: BodySpheres, spheres: np.ndarray, clamp: np.ndarray) -> np.ndarray:
    """`least_permissible_speeds` of `spheres` (indices into `body`), quasi-static where
    `clamp`: half the transient speed, as the force limit is half (`BodyRegion.force_limit`)."""
    return least_permissible_speeds(body)[spheres] / np.where(clamp, TRANSIENT_FACTOR, 1.0)


def clamped(body: BodySpheres, spheres: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Whether each of `spheres` (indices into `body`) could be clamped against the table by a
    robot approaching along `direction` (k×3, unit, from the robot toward the sphere)."""
    centres = body.centres[spheres]
    over = np.all(np.abs(centres[:, :2] - TABLE_POSITION[:2]) <= TABLE_HALF, axis=1)
    low = centres[:, 2] - body.radii[spheres] <= TABLE_POSITION[2] + CLAMP_REACH
    return over & low & (np.asarray(direction)[:, 2] <= CLAMP_SLOPE)


@dataclass(frozen=True)
class ContactJudgement:
    """One approach judged by Annex A: the region, whether it could be clamped, the robot's
    speed toward it [m/s], its effective mass along that direction [kg], the permissible speed
    [m/s], the force that speed implies [N] and the permissible force [N]."""

    time: float
    region: str
    clamped: bool
    speed: float
    robot_mass: float
    permissible_speed: float
    force: float
    force_limit: float
    gap: float  # the separation at that pair [m]; ≤ 0 a contact
    shape: str  # the robot shape that approached
    # speed ÷ permissible speed; inf at the head (beside it inside S_p, or toward it at all)
    ratio: float

    @property
    def within(self) -> bool:
        """Whether the standard permits it."""
        return self.ratio <= 1.0

    def to_json(self) -> dict:
        """The JSON-able judgement (m, m/s, kg, N; rounded)."""
        return {
            "time": round(self.time, 3),
            "region": self.region,
            "clamped": self.clamped,
            "shape": self.shape,
            "speed": round(self.speed, 3),
            "permissible_speed": round(self.permissible_speed, 3),
            "robot_mass": round(self.robot_mass, 2) if np.isfinite(self.robot_mass) else None,
            "force": round(self.force, 1),
            "force_limit": round(self.force_limit, 1),
            "gap": round(self.gap, 4),
            "within": self.within,
        }


def judge(region: BodyRegion, clamp: bool, speed: float, robot_mass: float) -> tuple[float, ...]:
    """(permissible speed [m/s], force implied [N], permissible force [N]) of the robot, of
    effective mass `robot_mass` [kg] (inf: rigid), approaching `region` at `speed` [m/s]."""
    reduced = 1.0 / (1.0 / region.mass + 1.0 / robot_mass)
    root = float(np.sqrt(reduced * region.stiffness))
    limit = float(region.force_limit(clamp))
    permissible = limit / root if region.touchable else 0.0
    return permissible, max(speed, 0.0) * root, limit if region.touchable else 0.0


__all__ = [
    "CHEST",
    "CLAMP_REACH",
    "HAND",
    "LOWER_ARM",
    "REGIONS",
    "SKULL",
    "TRANSIENT_FACTOR",
    "UPPER_ARM",
    "BodyRegion",
    "ContactJudgement",
    "clamped",
    "judge",
    "least_permissible_speeds",
    "least_speeds_at",
    "region_rows",
    "touchable",
]
