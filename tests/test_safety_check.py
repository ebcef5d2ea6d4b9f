"""The run's own check of separation (`hrc_drake.cell.run.safety_check`): S_h is the person's
actual travel toward the robot, so a hand that sets off toward the moving arm is judged by where
it went, not by its speed when it set off."""

import dataclasses

import numpy as np
import pytest

from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.separation import assess
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope, nearest_points
from hrc_drake.cell.run.safety_check import (
    AWAY,
    SafetySample,
    SafetyTrace,
    check_separation,
)
from hrc_drake.cell.ssm import bounded_travel
from hrc_drake.cell_models import CellDesign
from hrc_drake.scenario.safety import SafetyConfig
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.spec import load_spec

PERIOD = 0.02  # s between samples (the monitor's)
ACCELERATION = 5.0  # rad/s^2: T_s = 0.2 s at 1 rad/s
RADIUS = 0.04  # m, the probe sphere's
OPENING = 0.045  # m


@pytest.fixture(scope="module")
def envelope():
    return RobotEnvelope(CellDesign.of(load_spec()))


def _start(envelope):
    """The arm at its ready posture and a probe 0.5 m from the nearest robot shape, along the
    direction from that shape to it (+x of the gripper)."""
    q = np.array(Scenario().station.ur3.ready, dtype=float)
    R_WB, p_WB = envelope.pose(q, OPENING)
    probe = p_WB[-1] + np.array([0.0, 0.0, 0.5])
    shapes = envelope.shapes(None, True)
    pairs = nearest_points(shapes, R_WB, p_WB, probe[None, :])
    nearest = int(np.argmin(pairs.distance[:, 0]))
    return q, probe, pairs.direction[nearest, 0], float(pairs.distance[nearest, 0])


def _trace(q, v, commanded, centres) -> list[SafetySample]:
    """One sample a period for each body centre given, the arm moving at `v`."""
    return [
        SafetySample(
            time=k * PERIOD,
            q=q,
            v=np.asarray(v, dtype=float),
            commanded=np.asarray(commanded, dtype=float),
            opening=OPENING,
            carrying=None,
            body=BodySpheres(np.array([c]), np.array([RADIUS]), np.zeros((1, 3))),
        )
        for k, c in enumerate(centres)
    ]


def _approach(probe, direction, distance: float, steps: int = 30):
    """The probe at rest, then (from the second sample) closing `distance` along the
    direction toward the robot within 0.16 s, then still."""
    travel = np.clip((np.arange(steps) * PERIOD - 0.02) / 0.16, 0.0, 1.0) * distance
    return [probe - t * direction for t in travel]


MOVING = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # the shoulder turns at 1 rad/s
# Separation alone: the shoulder's turn carries the gripper past the probe slower than the
# contact speed, which `test_a_slow_robot_may_come_closer_than_s_p_but_not_to_the_head` covers.
SEPARATION_ALONE = SafetyConfig(contact_speed=0.0)


def test_a_hand_that_sets_off_toward_the_moving_arm_is_a_violation(envelope):
    """At rest when the arm moves, the hand comes to 7 cm of it within T_r + T_s, never
    touching: the check counts the violation, from where the hand went."""
    q, probe, direction, distance = _start(envelope)
    trace = _trace(q, MOVING, MOVING, _approach(probe, direction, distance - 0.07))
    result = check_separation(trace, envelope, SEPARATION_ALONE, ACCELERATION)
    assert result.violations >= 1 and result.least_margin < 0.0
    assert result.worst_time is not None and result.worst_time <= 0.2  # while it approached
    assert result.body_contacts == 0


def test_a_slow_pass_by_the_hand_is_permitted_and_by_the_head_is_not(envelope):
    """The gripper passes the hand slower than 0.25 m/s toward it: inside S_p, at a speed
    ISO/TS 15066 permits the hand (the check passes); the same pass beside the head does not:
    Annex A permits no contact there, so neither the arm moving inside S_p beside it."""
    q, probe, direction, distance = _start(envelope)
    centres = _approach(probe, direction, distance - 0.07)
    trace = _trace(q, MOVING, MOVING, centres)
    slow = check_separation(trace, envelope, SafetyConfig(), ACCELERATION)
    assert slow.violations >= 1 and slow.beyond_permissible == 0 and slow.passed
    assert slow.worst is None or slow.worst.speed < 0.25 < slow.worst.permissible_speed
    assert set(dict(slow.regions)) <= {"hand", AWAY}
    data = slow.to_json()
    assert data["steps_beyond_permissible_speed"] == 0 and data["passed"]
    assert sum(data["regions_inside_sp"].values()) == data["steps_inside_sp"]
    # The probe as the head of a body (the last of its five parts).
    head = [
        dataclasses.replace(
            sample,
            body=BodySpheres(
                np.repeat(sample.body.centres, 5, axis=0),
                np.full(5, RADIUS),
                np.zeros((5, 3)),
                ((0, 1), (1, 2), (2, 3), (3, 4), (4, 5)),
            ),
        )
        for sample in trace
    ]
    at_head = check_separation(head, envelope, SafetyConfig(), ACCELERATION)
    assert at_head.beyond_permissible >= 1 and not at_head.passed
    assert at_head.worst.region == "skull and forehead" and at_head.worst.permissible_speed == 0
    assert "FASTER than ISO/TS 15066 permits" in at_head.summary()


def test_a_hand_that_stays_or_moves_away_is_no_violation(envelope):
    q, probe, direction, distance = _start(envelope)
    config = SEPARATION_ALONE
    still = check_separation(_trace(q, MOVING, MOVING, [probe] * 30), envelope, config, 5.0)
    assert still.violations == 0 and 0.0 < still.least_margin < distance
    away = _approach(probe, -direction, 0.3)
    leaving = check_separation(_trace(q, MOVING, MOVING, away), envelope, config, ACCELERATION)
    assert leaving.violations == 0 and leaving.least_margin == pytest.approx(still.least_margin)


def test_the_check_is_the_same_whatever_the_monitor_is_set_to(envelope):
    """No setting of the monitor (on or off, its speed model, its band) changes the check; only
    the standard's constants do (here the hand's position uncertainty Z_d)."""
    q, probe, direction, distance = _start(envelope)
    trace = _trace(q, MOVING, MOVING, _approach(probe, direction, distance - 0.07))
    base = check_separation(trace, envelope, SEPARATION_ALONE, ACCELERATION)
    for changes in (
        {"enabled": False},
        {"human_speed": "constant"},
        {"hand_acceleration": 5.0},
        {"contact_speed": 2.0},
        {"slow_band": 0.5},
        {"separation": "reactive"},
    ):
        other = dataclasses.replace(SEPARATION_ALONE, **changes)
        assert check_separation(trace, envelope, other, ACCELERATION) == base
    wider = dataclasses.replace(SEPARATION_ALONE, human_uncertainty=0.15)
    assert check_separation(trace, envelope, wider, ACCELERATION).least_margin == pytest.approx(
        base.least_margin - 0.10
    )


def test_a_pushed_arm_or_a_still_one_is_no_violation_of_the_robot(envelope):
    q, probe, direction, distance = _start(envelope)
    config = SEPARATION_ALONE
    centres = _approach(probe, direction, distance - 0.07)
    pushed = check_separation(_trace(q, MOVING, np.zeros(6), centres), envelope, config, 5.0)
    assert pushed.violations == 0 and pushed.imposed >= 1
    still = check_separation(_trace(q, np.zeros(6), np.zeros(6), centres), envelope, config, 5.0)
    assert still.violations == 0 and still.imposed == 0
    assert not np.isfinite(still.least_margin) and still.to_json()["least_margin"] is None


def test_a_trace_takes_one_sample_a_period():
    trace = SafetyTrace(PERIOD)
    sample = _trace(np.zeros(6), np.zeros(6), np.zeros(6), [np.zeros(3)])[0]
    for now in np.arange(0.0, 0.1, 0.01):  # plant steps of 10 ms
        if trace.due(float(now)):
            trace.add(dataclasses.replace(sample, time=float(now)))
    assert [round(s.time, 3) for s in trace.samples] == [0.0, 0.02, 0.04, 0.06, 0.08]


def test_bounded_travel_speeds_up_to_the_cap_and_no_further():
    # From rest at 10 m/s^2 for 0.1 s: 0.05 m; for 0.3 s the cap 1.6 m/s is reached at 0.16 s.
    assert bounded_travel(0.0, 0.1, 10.0, 1.6) == pytest.approx(0.05)
    assert bounded_travel(0.0, 0.3, 10.0, 1.6) == pytest.approx(0.5 * 10 * 0.16**2 + 1.6 * 0.14)
    # A hand already at the cap, or faster, keeps its speed.
    assert bounded_travel(1.6, 0.3, 10.0, 1.6) == pytest.approx(0.48)
    assert bounded_travel(2.5, 0.3, 10.0, 1.6) == pytest.approx(0.75)


def test_the_planning_monitor_allows_for_the_hand_that_sets_off(envelope):
    """The approach the check counts as a violation: from the hand's speed at the first sample
    (still) alone there is room; the monitor bounds what the hand can reach within T_r + T_s
    (`safety.human_speed: tracked`, or the constant speeds) and finds none, and slows the arm."""
    q, probe, direction, distance = _start(envelope)
    trace = _trace(q, MOVING, MOVING, _approach(probe, direction, distance - 0.07))
    intent = MotionIntent(qdot=np.array(MOVING), moving=True, rate=1.0)
    first = trace[0]

    def reading(**changes):
        config = dataclasses.replace(SEPARATION_ALONE, **changes)
        return assess(envelope, q, first.v, first.body, intent, config, ACCELERATION, OPENING)

    as_if_held, bounded = reading(hand_acceleration=1e-6), reading()
    assert as_if_held.margin > 0.0 > bounded.margin
    assert bounded.limit < as_if_held.limit and bounded.short
    constant = reading(human_speed="constant")
    assert constant.margin <= bounded.margin and constant.short
