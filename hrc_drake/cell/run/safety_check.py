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
sensor reads as held. Of the violations, those where the robot also moved toward the person
faster than ISO 10218-1's reduced speed (0.25 m/s, `REDUCED_SPEED`), or toward the head at all,
are counted apart (`beyond_contact_speed`): the ones power and force limiting would not permit
either (`hrc_drake.cell.ssm`). A mode can change what the robot does, never this arithmetic: the
check reads `safety`'s constants (T_r, C, Z_d, Z_r) and no setting of the monitor's or the
safety function's (not `safety.contact_speed`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.separation_pipeline import (
    SeparationPipeline,
    pipeline_of,
    protective_separation,
)
from hrc_drake.cell.ssm import IMPOSED_SPEED, REDUCED_SPEED, beyond_contact_speed, stopping_time
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


@dataclass(frozen=True)
class SafetyCheck:
    """The check's figures over a run (`simulate --json` `safety`: `violations`,
    `least_margin`, `body_contacts`)."""

    steps: int = 0
    violations: int = 0  # samples where the robot moved under its own command inside S_p
    least_margin: float = float("inf")  # least separation − S_p while it did [m]
    body_contacts: int = 0  # samples where a robot shape touched a body sphere
    imposed: int = 0  # samples inside S_p while the arm was moved from outside (a push)
    worst_time: float | None = None  # when the least margin was reached [s]
    # violations where the robot also moved toward the person faster than REDUCED_SPEED (or
    # toward the head): what power and force limiting would not permit either
    beyond_contact_speed: int = 0

    def to_json(self) -> dict:
        """The JSON-able figures (distances in m, rounded to 0.1 mm; None: the robot never
        moved beside a body)."""
        finite = np.isfinite(self.least_margin)
        return {
            "violations": self.violations,
            "least_margin": round(float(self.least_margin), 4) if finite else None,
            "body_contacts": self.body_contacts,
            "imposed_violations": self.imposed,
            "violations_beyond_contact_speed": self.beyond_contact_speed,
            "checked_steps": self.steps,
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


def check_separation(
    samples: list[SafetySample],
    envelope: RobotEnvelope | SeparationPipeline,
    config: SafetyConfig,
    joint_acceleration: float,
) -> SafetyCheck:
    """The check of the module docstring over a run's `samples`; `envelope`: the check's own
    model of the robot, or a `SeparationPipeline` of one."""
    pipeline = pipeline_of(envelope)
    violations = imposed = contacts = beyond = 0
    least, worst = float("inf"), None
    for k, sample in enumerate(samples):
        body = sample.body
        if len(body.radii) == 0:
            continue
        geometry = pipeline.pairs(sample.q, sample.opening, sample.carrying, body)
        gap = geometry.gap
        contacts += int(gap.min() <= 0.0)
        speed = float(np.abs(sample.v).max(initial=0.0))
        if speed <= config.moving_speed:
            continue
        t_s = stopping_time(sample.v, joint_acceleration)
        v_r = np.maximum(0.0, geometry.robot_speeds(sample.v[None, :])[0])
        s_h = _travel_toward(samples, k, config.reaction_time + t_s, geometry.pairs.direction)
        s_p = protective_separation(geometry, v_r, t_s, config, travel=s_h)
        margin = float((gap - s_p).min())
        fast = bool(((gap < s_p) & beyond_contact_speed(v_r, REDUCED_SPEED, body)).any())
        if np.abs(sample.v - sample.commanded).max(initial=0.0) > IMPOSED_SPEED:
            imposed += int(margin < 0.0)
            continue
        violations += int(margin < 0.0)
        beyond += int(fast)
        if margin < least:
            least, worst = margin, sample.time
    return SafetyCheck(
        steps=len(samples),
        violations=violations,
        least_margin=least,
        body_contacts=contacts,
        imposed=imposed,
        worst_time=worst,
        beyond_contact_speed=beyond,
    )


__all__ = [
    "SafetyCheck",
    "SafetySample",
    "SafetyTrace",
    "check_separation",
]
