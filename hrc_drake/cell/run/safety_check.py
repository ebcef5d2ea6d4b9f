"""The run's own check of separation, the same for every mode and setting (ISO/TS 15066 §5.5.4).

The separation monitor of the controller decides, step by step, from what it can know: the
person's speed *now*. Whether the robot then kept the protective separation distance is a fact
only the run's whole record can settle, so it is judged here, after the run, from samples of
what the cell measured, one per monitor period, and from nothing the controller believed:

    S_p = S_h + v_r T_r + S_s + C + Z_d + Z_r

with S_h the person's *actual* travel toward the robot over the next T_r + T_s — the largest
distance each body sphere came closer along the direction to the robot shape, over the samples
from this one to the first at or past T_r + T_s later (so the window never falls short of it) —
and T_s, S_s the robot's stopping time and distance from its measured joint speeds
(T_s = max_j |q̇_j| / a, S_s = v_r T_s / 2, as the monitor's). A sample counts as a violation when
the robot moved under its own command (a joint faster than `safety.moving_speed`, none faster than
commanded by more than `IMPOSED_SPEED`: a push is the person's doing and is counted apart) and
some robot shape was closer to some body sphere than S_p. The robot's shapes are the
controller's conservative envelope (`RobotEnvelope`: never farther from a point than the true
geometry) posed from the measured joints and gripper opening, with the part the configuration
sensor reads as held.

Inside S_p power and force limiting may still permit the approach (ISO/TS 15066 §5.5.5), so each
violation is judged by Annex A (`hrc_drake.cell.contact_limits`): of the pairs inside S_p where
the robot moves toward the body, the one furthest beyond (or nearest) the speed its body region
permits, with the robot's effective mass along that direction at that point of its shapes from
the check's own plant (`hrc_drake.cell.effective_mass`), transient or, where the region could be
clamped against the table, quasi-static; never toward the head. Every sample where a robot shape
touches a body sphere is judged the same way, with the force the speed implies. The run passes
(`SafetyCheck.passed`) when no violation is beyond the permissible speed and no contact beyond the
permissible force. A mode can change what the robot does, never this arithmetic: the check reads
`safety`'s constants (T_r, C, Z_d, Z_r) and no setting of the monitor's or the safety function's
(not `safety.contact_speed`). Its T_r is the robot's reaction and the body sensor's response
together: the run adds a tracker's period and latency bound under `sensors:`
(`hrc_drake.cell.run.loop`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from hrc_drake.cell.contact_limits import (
    REGIONS,
    ContactJudgement,
    clamped,
    judge,
    least_speeds_at,
    region_rows,
    touchable,
)
from hrc_drake.cell.effective_mass import EffectiveMass
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.separation_pipeline import (
    SeparationPipeline,
    pipeline_of,
    protective_separation,
)
from hrc_drake.cell.ssm import IMPOSED_SPEED, stopping_time
from hrc_drake.scenario.safety import SafetyConfig


@dataclass(frozen=True)
class SafetySample:
    """What the cell measured at one monitor step: the arm's joints (positions [rad] and
    velocities [rad/s], UR3_JOINTS order), the velocities commanded to it, the gripper's
    opening [m], the part it holds (None: none), and the tracked body."""

    time: float
    q: np.ndarray
    v: np.ndarray
    commanded: np.ndarray
    opening: float
    carrying: str | None
    body: BodySpheres


CONTACTS_LISTED = 20  # contact judgements the JSON lists (the count has them all)
AWAY = "moving away from the person"  # a violation where the arm approached no body sphere


@dataclass(frozen=True)
class SafetyCheck:
    """The check's figures over a run (`simulate --json` `safety.check`)."""

    steps: int = 0
    violations: int = 0  # samples where the robot moved under its own command inside S_p
    least_margin: float = float("inf")  # least separation − S_p while it did [m]
    body_contacts: int = 0  # samples where a robot shape touched a body sphere
    imposed: int = 0  # samples inside S_p while the arm was moved from outside (a push)
    worst_time: float | None = None  # when the least margin was reached [s]
    # violations where the robot moved toward a body region faster than Annex A permits it
    beyond_permissible: int = 0
    contacts_beyond: int = 0  # contacts at a force beyond the region's permissible one
    # the approach inside S_p nearest (or most beyond) its permissible speed, and the contacts
    worst: ContactJudgement | None = None
    contacts: tuple[ContactJudgement, ...] = ()
    regions: tuple[tuple[str, int], ...] = ()  # the region approached at each violation
    reaction_time: float = 0.0  # the T_r judged by [s]

    @property
    def passed(self) -> bool:
        """Whether the standard permits all the run did: nothing inside S_p faster than its
        body region permits, no contact beyond its permissible force."""
        return self.beyond_permissible == 0 and self.contacts_beyond == 0

    def summary(self) -> str:
        """In words: whether the arm kept S_p and, where it was inside it, whether at a speed
        the body region it approached permits (`simulate`'s safety line)."""
        steps = f"{self.steps:,} checked step(s)"
        if self.violations == 0:
            text = f"kept S_p at every one of {steps}"
        else:
            parts = [
                f"approaching the {region} at {n:,}" if region != AWAY else f"{AWAY} at {n:,}"
                for region, n in self.regions
            ]
            text = f"came inside S_p at {self.violations:,} of {steps} ({', '.join(parts)})"
            if self.beyond_permissible:
                text += (
                    f"; at {self.beyond_permissible:,} FASTER than ISO/TS 15066 permits toward "
                    "that body region"
                )
            elif any(region != AWAY for region, _ in self.regions):
                text += ", every approach at a speed ISO/TS 15066 permits there"
        w = self.worst
        if w is not None and w.force_limit == 0.0:  # a region that permits no contact
            text += f"; beside the {w.region} at {w.time:.2f} s, where no contact is permitted"
        elif w is not None:
            text += (
                f"; nearest the limit {w.speed:.2f} m/s toward the {w.region}"
                f"{' (could be clamped)' if w.clamped else ''} at {w.time:.2f} s, "
                f"{w.permissible_speed:.2f} permitted"
            )
        if self.body_contacts:
            text += f"; touched the person at {self.body_contacts:,} step(s), " + (
                f"{self.contacts_beyond:,} BEYOND the permissible force"
                if self.contacts_beyond
                else "each within the permissible force"
            )
        if self.imposed:
            text += f"; pushed inside S_p from outside at {self.imposed:,}"
        return text

    def to_json(self) -> dict:
        """The JSON-able figures (m, m/s, N; rounded; None: never reached)."""
        finite = np.isfinite(self.least_margin)
        return {
            "passed": self.passed,
            "checked_steps": self.steps,
            "reaction_time": round(self.reaction_time, 4),
            "steps_inside_sp": self.violations,
            "steps_beyond_permissible_speed": self.beyond_permissible,
            "regions_inside_sp": dict(self.regions),
            "least_margin": round(float(self.least_margin), 4) if finite else None,
            "worst_time": None if self.worst_time is None else round(self.worst_time, 3),
            "nearest_the_limit": None if self.worst is None else self.worst.to_json(),
            "pushed_inside_sp": self.imposed,
            "body_contacts": self.body_contacts,
            "contacts_beyond_limits": self.contacts_beyond,
            "contacts": [c.to_json() for c in self.contacts[:CONTACTS_LISTED]],
        }


@dataclass
class SafetyTrace:
    """The samples of a run, one per `period` (`add` takes one when it is due)."""

    period: float
    samples: list[SafetySample] = field(default_factory=list)
    next_time: float = 0.0

    def due(self, now: float) -> bool:
        """Whether a sample is due at simulated time `now`."""
        return now >= self.next_time - 1e-9

    def add(self, sample: SafetySample) -> None:
        """Keep `sample`; the next is due a period after it."""
        self.samples.append(sample)
        self.next_time = sample.time + self.period


def _travel_toward(
    samples: list[SafetySample], k: int, window: float, direction: np.ndarray
) -> np.ndarray:
    """(shapes × spheres) the largest distance each body sphere of sample `k` came closer
    along `direction` (unit, from the robot shape toward the sphere) over the samples from `k`
    to the first at or past `window` seconds later; 0 for a sphere that only moved away."""
    start = samples[k]
    travel = np.zeros(direction.shape[:2])
    for later in samples[k + 1 :]:
        if len(later.body.radii) != len(start.body.radii):
            break  # another body (or none): the tracker lost this one
        moved = later.body.centres - start.body.centres
        travel = np.maximum(travel, -np.einsum("nj,mnj->mn", moved, direction))
        if later.time >= start.time + window - 1e-9:
            break
    return travel


class _Judge:
    """Judges the pairs of one sample by Annex A (`hrc_drake.cell.contact_limits`): the robot's
    effective mass at each pair's nearest point, from the check's own plant."""

    def __init__(self, envelope: RobotEnvelope):
        self.masses = EffectiveMass(envelope)

    def worst(
        self, sample: SafetySample, geometry, v_r, mask, beside_head: bool
    ) -> ContactJudgement | None:
        """The judgement of the pair in `mask` (m×n) the furthest beyond, or nearest, its
        permissible speed; None for no pair. At the head any pair is beyond with
        `beside_head` (inside S_p while the arm moves: a contact there is never permitted),
        else one the arm moves toward. Only the pairs that the bound at any effective mass
        (`least_permissible_speeds`) does not clear are weighed with the pose's own mass, and
        the bound's worst pair with them."""
        shape, sphere = np.nonzero(mask)
        if len(shape) == 0:
            return None
        body, pairs = sample.body, geometry.pairs
        direction = pairs.direction[shape, sphere]
        clamp = clamped(body, sphere, direction)
        bound = least_speeds_at(body, sphere, clamp)
        speed = v_r[shape, sphere]
        head = ~touchable(body)[sphere] & (beside_head | (speed > 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(head, np.inf, np.where(bound > 0.0, speed / bound, 0.0))
        weigh = np.union1d(np.flatnonzero(ratio > 1.0), [int(np.argmax(ratio))])
        masses = self.masses.along(
            sample.q,
            sample.opening,
            sample.carrying,
            geometry.robot.shapes,
            shape[weigh],
            pairs.witness[shape[weigh], sphere[weigh]],
            direction[weigh],
        )
        rows = region_rows(body)[sphere[weigh]]
        found = None
        for k, pick in enumerate(weigh):
            region = REGIONS[rows[k]]
            permissible, force, limit = judge(region, bool(clamp[pick]), speed[pick], masses[k])
            over = np.inf if head[pick] else speed[pick] / permissible
            if found is None or over > found.ratio:
                found = ContactJudgement(
                    time=sample.time,
                    region=region.name,
                    clamped=bool(clamp[pick]),
                    speed=float(speed[pick]),
                    robot_mass=float(masses[k]),
                    permissible_speed=permissible,
                    force=force,
                    force_limit=limit,
                    gap=float(geometry.gap[shape[pick], sphere[pick]]),
                    shape=geometry.robot.shapes.names[shape[pick]],
                    ratio=float(over),
                )
        return found


def _further(a: ContactJudgement | None, b: ContactJudgement | None) -> ContactJudgement | None:
    """Of two judgements, the one further beyond (or nearer) its permissible speed."""
    if a is None or b is None:
        return a or b
    return b if b.ratio > a.ratio else a


def check_separation(
    samples: list[SafetySample],
    envelope: RobotEnvelope | SeparationPipeline,
    config: SafetyConfig,
    joint_acceleration: float,
) -> SafetyCheck:
    """The check of the module docstring over a run's `samples`; `envelope`: the check's own
    model of the robot, or a `SeparationPipeline` of one."""
    pipeline = pipeline_of(envelope)
    judge_pairs = _Judge(pipeline.envelope)
    violations = imposed = beyond = 0
    least, worst_time, worst = float("inf"), None, None
    touches: list[ContactJudgement] = []
    regions: Counter[str] = Counter()
    for k, sample in enumerate(samples):
        body = sample.body
        if len(body.radii) == 0:
            continue
        geometry = pipeline.pairs(sample.q, sample.opening, sample.carrying, body)
        gap = geometry.gap
        v_r = np.maximum(0.0, geometry.robot_speeds(sample.v[None, :])[0])
        if gap.min() <= 0.0:
            touches.append(judge_pairs.worst(sample, geometry, v_r, gap <= 0.0, beside_head=False))
        speed = float(np.abs(sample.v).max(initial=0.0))
        if speed <= config.moving_speed:
            continue
        t_s = stopping_time(sample.v, joint_acceleration)
        s_h = _travel_toward(samples, k, config.reaction_time + t_s, geometry.pairs.direction)
        s_p = protective_separation(geometry, v_r, t_s, config, travel=s_h)
        margin = float((gap - s_p).min())
        if np.abs(sample.v - sample.commanded).max(initial=0.0) > IMPOSED_SPEED:
            imposed += int(margin < 0.0)
            continue
        if margin < least:
            least, worst_time = margin, sample.time
        if margin >= 0.0:
            continue
        violations += 1
        toward = (gap < s_p) & ((v_r > 0.0) | ~touchable(body)[None, :])
        approach = judge_pairs.worst(sample, geometry, v_r, toward, beside_head=True)
        regions[approach.region if approach is not None else AWAY] += 1
        beyond += int(approach is not None and not approach.within)
        worst = _further(worst, approach)
    return SafetyCheck(
        steps=len(samples),
        violations=violations,
        least_margin=least,
        body_contacts=len(touches),
        imposed=imposed,
        worst_time=worst_time,
        beyond_permissible=beyond,
        contacts_beyond=sum(not touch.within for touch in touches),
        worst=worst,
        contacts=tuple(touches),
        regions=tuple(regions.most_common()),
        reaction_time=config.reaction_time,
    )


__all__ = [
    "SafetyCheck",
    "SafetySample",
    "SafetyTrace",
    "check_separation",
]
