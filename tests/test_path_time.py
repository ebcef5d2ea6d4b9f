"""The path–time timing of a motion against a forecast (`hrc_drake.motion.path_time`)."""

import itertools

import numpy as np
import pytest
from pydrake.trajectories import PiecewisePolynomial

from hrc_drake.motion.clearance import (
    SAMPLE,
    Occupancy,
    forecast_delay,
    motion_path,
    time_around,
)
from hrc_drake.motion.path_time import (
    LEVELS,
    PAYS,
    POSE_STEP,
    STEP,
    SpeedCap,
    path_time_around,
    reactive_profile,
    slip,
    speed_cap,
    time_path,
)
from hrc_drake.motion.plan import MotionTiming, Plan, Segment, Stage

ACCELERATION = 5.0  # rad/s²
# rad/s²: a ramp slow enough that an arm which stands back for a hand and passes it at speed
# arrives over a step (PAYS) before monitoring alone, which sets off from rest at the hand
SLOW = 1.0
DURATION = 3.0  # s: the one motion's time at full speed


def _plan(duration: float = DURATION, reach: float = 1.0, opening: float = 0.0) -> Plan:
    """One motion from rest to rest: joint 0 goes 0 → `reach` over [0, duration] (read as the
    robot's x by the scale functions below), the gripper held at `opening` [m]."""
    knots = np.zeros((6, 2))
    knots[0, 1] = reach
    trajectory = PiecewisePolynomial.CubicHermite([0.0, duration], knots, np.zeros((6, 2)))
    gripper = PiecewisePolynomial.ZeroOrderHold([0.0, duration], np.full((1, 2), opening))
    segments = (
        Segment(Stage.APPROACH, 0.0, 0.0),
        Segment(Stage.GRASP, 0.0, 0.0),
        Segment(Stage.CARRY, 0.0, duration),
    )
    motions = (MotionTiming("only", 0.0, duration, duration),)
    return Plan(
        "F1", "part", frozenset(), trajectory, gripper, duration, duration, duration, segments,
        (), motions,
    )  # fmt: skip


def _graded(q, qdot, opening, carrying, centres, radii, velocities) -> float:
    """Monitoring's stand-in: a stop within 0.15 m of a body sphere, full speed past 0.45 m,
    in between in proportion."""
    robot = np.array([q[0], 0.0, 0.0])
    gap = (np.linalg.norm(centres - robot, axis=1) - radii).min()
    return float(np.clip((gap - 0.15) / 0.3, 0.0, 1.0))


def _stops_near(q, qdot, opening, carrying, centres, radii, velocities) -> float:
    """A monitor that only stops: within 0.3 m of a body sphere, else full speed."""
    return 0.0 if _graded(q, qdot, opening, carrying, centres, radii, velocities) < 0.5 else 1.0


def _sits(at: float, until: float, start: float = 0.0, end: float = 12.0) -> Occupancy:
    """A hand at x = `at` on the path until `until`, then far away."""
    times = np.arange(start, end, STEP)
    centres = np.array([[[at if t < until else 5.0, 0.0, 0.0]] for t in times])
    return Occupancy(times, centres, np.array([0.05]), np.zeros_like(centres))


def _empty() -> Occupancy:
    return Occupancy(np.zeros(0), np.zeros((0, 1, 3)), np.array([0.05]), np.zeros((0, 1, 3)))


def _arrival_after_wait(plan: Plan, occupancy: Occupancy) -> float:
    """When the arm arrives if it waits as `time_around` times it, then follows the plan with
    the monitor underneath (monitoring alone after the wait)."""
    holds = time_around(plan, 0.0, 0.0, occupancy, _graded, max_wait=6.0)
    wait = holds[0].until if holds else 0.0
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    return reactive_profile(path, 0.0, occupancy, _graded, ACCELERATION, wait=wait).arrival


def test_a_hand_that_sits_on_the_path_for_2_s_is_passed_sooner_than_by_waiting_or_reacting():
    plan = _plan()
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    sits = _sits(at=0.6, until=2.0)
    profile = time_path(path, 0.0, sits, _graded, ACCELERATION, longest=6.0)
    assert profile is not None
    reactive = reactive_profile(path, 0.0, sits, _graded, ACCELERATION)
    waiting = _arrival_after_wait(plan, sits)
    assert profile.arrival <= reactive.arrival + 1e-9
    assert profile.arrival <= waiting + 1e-9
    # The hand costs it something, and it is strictly better than waiting here.
    assert profile.arrival > DURATION
    assert profile.arrival < waiting - STEP
    # It sets off at once and slows mid-path for the hand instead of waiting at the start.
    assert profile.wait == 0.0
    on_the_way = (profile.taus > 0.1) & (profile.taus < DURATION - 0.1)
    assert profile.speeds[on_the_way].min() < 0.5
    # It keeps to the monitor's limit against the forecast at every step.
    for t, tau, s in zip(profile.times, profile.taus, profile.speeds, strict=True):
        i = sits.at(t)
        q = plan.trajectory.value(tau).ravel()
        qdot = plan.trajectory.EvalDerivative(tau, 1).ravel()
        allowed = _graded(q, qdot, 0.0, None, sits.centres[i], sits.radii, sits.velocities[i])
        assert s <= allowed + 0.1  # the pose is the nearest sampled one (0.1 s of plan time)


def test_between_two_hands_it_stops_mid_path_and_goes_on_when_the_one_ahead_leaves():
    plan = _plan()
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    # One hand sits near the path's end until 3 s, another comes to its start at 1.5 s: the
    # arm must leave at once and stand between them until the one ahead has left.
    ahead, behind = _sits(at=1.0, until=3.0), _sits(at=0.0, until=12.0, start=1.5)
    times = np.arange(0.0, 12.0, STEP)
    centres = np.concatenate([ahead.centres, np.full((len(times), 1, 3), [5.0, 0.0, 0.0])], axis=1)
    centres[15:, 1] = behind.centres[:, 0]
    both = Occupancy(times, centres, np.array([0.05, 0.05]), np.zeros_like(centres))
    profile = time_path(path, 0.0, both, _stops_near, ACCELERATION, longest=6.0)
    assert profile.wait < 1.0  # it leaves before the hand behind comes
    between = (profile.taus > 1.0) & (profile.taus < 2.0)
    assert profile.speeds[between].min() == 0.0  # stops mid-path
    stopped = between & (profile.speeds == 0.0)
    assert profile.times[stopped].max() < 3.0 <= profile.arrival  # and goes on
    assert profile.arrival < 3.0 + DURATION
    # Monitoring alone gets there too here, never sooner; waiting at the start is held by
    # the hand that comes there.
    alone = reactive_profile(path, 0.0, both, _stops_near, ACCELERATION)
    assert profile.arrival <= alone.arrival + 1e-9
    holds = time_around(plan, 0.0, 0.0, both, _stops_near, max_wait=6.0)
    assert not holds or profile.arrival < holds[0].until + DURATION


@pytest.mark.parametrize("reaction", [None, 0.1])
@pytest.mark.parametrize("at", [0.2, 0.5, 0.8, 1.0])
@pytest.mark.parametrize("until", [0.5, 1.5, 2.5, 4.0])
def test_never_later_than_monitoring_alone_after_any_wait_against_an_exact_forecast(
    at, until, reaction
):
    """Monitoring alone, after any wait at the start up to the longest, is a timing the search
    considers: its arrival is never later (with the monitor's own limit, and with the limit
    held over the reaction and stopping window)."""
    plan = _plan()
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    sits = _sits(at, until)
    profile = time_path(path, 0.0, sits, _graded, ACCELERATION, longest=6.0, reaction=reaction)
    for wait in np.arange(0.0, 6.0 + 1e-9, 0.5):
        alone = reactive_profile(path, 0.0, sits, _graded, ACCELERATION, wait=wait, **{
            "reaction": reaction
        })  # fmt: skip
        assert profile.arrival <= alone.arrival + 1e-9


def _blocks_then_stands_beside(until: float = 4.0) -> Occupancy:
    """A hand on the path (x = 0.6) until `until`, then beside it for good (0.4 m off x = 0.5),
    near enough that the monitor slows the arm as it passes, whenever that is."""
    times = np.arange(0.0, 12.0, STEP)
    centres = np.array([[[0.6, 0.0, 0.0] if t < until else [0.5, 0.4, 0.0]] for t in times])
    return Occupancy(times, centres, np.array([0.05]), np.zeros_like(centres))


def test_the_monitor_is_asked_about_the_gripper_at_the_plans_opening():
    """Both timings ask the forecast monitor about each pose with the gripper's opening there:
    a monitor that stops the arm only when its fingers are open wide (they reach a hand on the
    path) makes the open plan wait for the hand and lets the closed one go at once."""

    def stops_wide_fingers(q, qdot, opening, carrying, centres, radii, velocities) -> float:
        near = _graded(q, qdot, opening, carrying, centres, radii, velocities) < 1.0
        return 0.0 if opening > 0.05 and near else 1.0

    sits = _sits(at=0.6, until=2.0)
    closed, wide = _plan(opening=0.02), _plan(opening=0.1)
    assert np.all(motion_path(closed, 0.0, DURATION, POSE_STEP).opening == 0.02)
    assert time_around(closed, 0.0, 0.0, sits, stops_wide_fingers, 6.0) == ()
    assert len(time_around(wide, 0.0, 0.0, sits, stops_wide_fingers, 6.0)) == 1
    for plan, slowed in ((closed, False), (wide, True)):
        asked: list[float] = []

        def recorded(q, qdot, opening, *rest, asked=asked) -> float:
            asked.append(opening)
            return stops_wide_fingers(q, qdot, opening, *rest)

        path_time_around(plan, 0.0, 0.0, 0.0, sits, recorded, 6.0, ACCELERATION)
        assert asked and set(asked) == {plan.gripper.value(0.0).item()}
        path = motion_path(plan, 0.0, DURATION, POSE_STEP)
        profile = time_path(path, 0.0, sits, stops_wide_fingers, ACCELERATION, longest=6.0)
        assert (profile.arrival > DURATION + STEP) == slowed


def test_a_timing_is_followed_only_where_it_arrives_a_step_before_monitoring_alone():
    """With a slow ramp (1 rad/s²) and a monitor that only stops, the arm that waits back for
    the hand on its path passes it at speed: 0.17 s sooner than monitoring alone, which stops
    at the hand and sets off from rest. That timing is followed (a hold, a cap). Against a
    graded monitor the best timing gains 0.01 s, less than PAYS: the motion is left to the
    monitor, with neither a hold nor a cap, and so costs nothing either."""
    plan, sits = _plan(), _sits(at=0.6, until=2.0)
    path = motion_path(plan, 0.0, DURATION, POSE_STEP)
    for monitor, pays in ((_stops_near, True), (_graded, False)):
        best = time_path(path, 0.0, sits, monitor, SLOW, longest=6.0)
        alone = reactive_profile(path, 0.0, sits, monitor, SLOW)
        assert best.arrival <= alone.arrival + 1e-9
        assert (best.arrival <= alone.arrival - PAYS) == pays
        timing = path_time_around(plan, 0.0, 0.0, 0.0, sits, monitor, 6.0, SLOW)
        assert bool(timing.holds) == bool(timing.caps) == pays
        if pays:
            assert timing.holds[0].until == pytest.approx(best.wait)


def test_the_forecast_delay_asks_the_monitor_once_per_pose_and_sample_over_every_wait():
    """The waits a motion tries meet the same (pose, forecast sample) pairs again: with a
    shared memo each is asked once, and every delay is the one asked afresh."""
    plan, sits = _plan(), _sits(at=0.6, until=2.0)
    path = motion_path(plan, 0.0, DURATION, SAMPLE)
    asked = []

    def counted(*args) -> float:
        asked.append(1)
        return _graded(*args)

    memo: dict = {}
    begins = np.arange(0.0, 3.0, 0.2)
    shared = [forecast_delay(path, b, sits, counted, memo) for b in begins]
    once = len(asked)
    fresh = [forecast_delay(path, b, sits, counted) for b in begins]
    assert shared == fresh and shared[0] > 0.5
    assert once == len(memo) < len(asked) - once


def test_clear_only_waits_only_where_a_wait_clears_the_motion():
    """Separation alone: a wait after which the monitor still slows the motion is not taken
    (the cheapest wait would be); a wait that clears it is, as without `clear_only`."""
    plan = _plan()
    stands = _blocks_then_stands_beside()
    cheapest = time_around(plan, 0.0, 0.0, stands, _graded, max_wait=6.0)
    assert len(cheapest) == 1 and cheapest[0].until > 0.0  # the premise: it would wait
    assert time_around(plan, 0.0, 0.0, stands, _graded, 6.0, clear_only=True) == ()
    assert time_around(plan, 0.0, 0.0, stands, _graded, 6.0, slowing_ok=True, clear_only=True) == ()
    leaves = _sits(at=0.6, until=2.0)
    clearing = time_around(plan, 0.0, 0.0, leaves, _graded, max_wait=6.0)
    assert len(clearing) == 1
    assert time_around(plan, 0.0, 0.0, leaves, _graded, 6.0, clear_only=True) == clearing


def test_with_a_reaction_time_it_keeps_below_the_limit_while_it_could_still_be_stopping():
    """A hand far off that comes onto the path at 2 s: with T_r the arm keeps below the limit
    the monitor will set over the next T_r + T_s, not only the one it sets now."""
    plan = _plan()
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    times = np.arange(0.0, 12.0, STEP)
    centres = np.array([[[0.6 if 2.0 <= t < 4.0 else 5.0, 0.0, 0.0]] for t in times])
    comes = Occupancy(times, centres, np.array([0.05]), np.zeros_like(centres))
    reaction = 0.1
    profile = time_path(path, 0.0, comes, _graded, ACCELERATION, longest=6.0, reaction=reaction)
    for t, tau, s in zip(profile.times, profile.taus, profile.speeds, strict=True):
        q = plan.trajectory.value(tau).ravel()
        qdot = plan.trajectory.EvalDerivative(tau, 1).ravel()
        window = reaction + np.abs(qdot).max() / ACCELERATION
        ahead = [comes.at(t + d) for d in np.arange(0.0, window + STEP, STEP)]
        allowed = min(
            _graded(q, qdot, 0.0, None, comes.centres[i], comes.radii, comes.velocities[i])
            for i in ahead
            if i is not None
        )
        assert s <= allowed + 0.1  # to the pose sampling (0.1 s of plan time)
    # Without it, the arm is still moving fast when the hand arrives.
    bare = time_path(path, 0.0, comes, _graded, ACCELERATION, longest=6.0)
    at_two = np.searchsorted(bare.times, 1.9)
    assert bare.speeds[at_two] > profile.speeds[at_two]


def test_with_nothing_forecast_it_runs_the_plan_at_full_speed():
    plan = _plan()
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    profile = time_path(path, 2.0, _empty(), _graded, ACCELERATION)
    assert np.all(profile.speeds == 1.0)
    assert profile.arrival == pytest.approx(2.0 + DURATION, abs=STEP / LEVELS)
    assert path_time_around(plan, 0.0, 2.0, 0.0, _empty(), _graded, 6.0, ACCELERATION).caps == ()


def test_the_speed_changes_within_the_joint_acceleration_limit():
    # A slow arm limit, so that the ramp binds: Δs ≤ a STEP / max |q̇| per step.
    acceleration = 0.5
    plan = _plan(reach=1.5)
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    sits = _sits(at=0.9, until=2.5)
    profile = time_path(path, 0.0, sits, _graded, acceleration, longest=6.0)
    changes = np.abs(np.diff(profile.speeds))
    assert changes.max() > 0.0
    for k, change in enumerate(changes):
        fast = np.abs(plan.trajectory.EvalDerivative(profile.taus[k + 1], 1)).max()
        bound = acceleration * STEP / max(fast, 1e-9)
        # The ramp is floored to a level and taken at the faster of the poses about it; at
        # least one level a step (1/LEVELS) is always allowed.
        assert change <= max(bound * 1.05, 1.0 / LEVELS) + 1e-9


def test_the_plan_timing_caps_the_speed_where_it_goes_slower_than_the_monitor_allows():
    plan = _plan()
    # Under way at full speed at plan time 0.5, a hand near the path's end until 3 s: the arm
    # brakes back from the hand (where the monitor alone would go on to it and stop there),
    # and goes on before the hand has left, to pass at speed (SLOW ramp: that pays).
    sits = _sits(0.8, 3.0)
    timing = path_time_around(plan, 0.5, 0.0, 1.0, sits, _stops_near, 6.0, SLOW)
    assert timing.holds == ()  # under way: no wait at a rest point
    (cap,) = timing.caps
    assert (cap.tau0, cap.tau1, cap.start) == (0.5, DURATION, 0.0)
    assert min(cap.speeds) == 0.0
    # The cap is the lower of this step's speed and the next one's, 1 past the timing.
    stopped = int(np.argmax(np.array(cap.speeds) == 0.0))
    k = stopped + int(np.argmax(np.array(cap.speeds[stopped:]) > 0.0))
    assert 0.0 == speed_cap(timing.caps, (k - 1) * STEP + 0.01, 1.0) < cap.speeds[k]
    assert speed_cap(timing.caps, k * STEP + 0.01, 1.0) == min(cap.speeds[k : k + 2])
    assert speed_cap(timing.caps, 100.0, 1.0) == 1.0
    assert speed_cap(timing.caps, 0.0, 0.2) == 1.0  # off the timed part
    # An arm off its timing slips; on time it does not.
    now = (k - 0.5) * STEP
    assert slip(timing.caps, now, cap.tau_at(now)) == pytest.approx(0.0)
    assert slip(timing.caps, now, cap.tau_at(now) + 0.3) == pytest.approx(0.3)


def test_the_cap_leaves_the_steps_at_the_monitors_limit_to_the_monitor():
    """Where the timing goes as fast as the monitor allows against the forecast, the cap is 1
    (the monitor's own, unquantised limit governs); where it goes slower by choice, the cap is
    its speed."""
    plan = _plan()
    sits = _sits(0.6, 2.0)
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    profile = time_path(path, 0.0, sits, _stops_near, SLOW, longest=6.0)
    # at_limit: the level the monitor allows at the step's pose (the nearest sampled one) is
    # no higher than the one taken (or the ramp keeps it lower as it speeds up, SLOW).
    for t, tau, s, at_limit in zip(
        profile.times, profile.taus, profile.speeds, profile.at_limit, strict=True
    ):
        p = int(np.argmin(np.abs(path.taus - tau)))
        i = sits.at(t)
        allowed = _stops_near(path.q[p], path.qdot[p], 0.0, None, sits.centres[i], sits.radii, 0)
        if int(np.floor(allowed * LEVELS + 1e-6)) <= round(s * LEVELS):
            assert at_limit
        if not at_limit:
            assert s < allowed
    assert profile.at_limit.any() and not profile.at_limit.all()
    timing = path_time_around(plan, 0.0, 0.0, 0.0, sits, _stops_near, 6.0, SLOW)
    (cap,) = timing.caps
    # The cap starts where the wait at the motion's start (a hold) ends.
    at_limit, chosen = profile.at_limit[round(profile.wait / STEP) :], profile.speeds
    chosen = chosen[round(profile.wait / STEP) :]
    speeds = np.array(cap.speeds)
    assert np.all(speeds[at_limit] == 1.0)
    assert np.array_equal(speeds[~at_limit], chosen[~at_limit])
    assert (~at_limit).any()


def test_a_hand_on_the_path_past_the_longest_wait_is_waited_for_at_most_that_long():
    plan = _plan()
    # The hand sits where the arm starts: it may not move until the hand leaves at 3 s.
    sits = _sits(at=0.0, until=3.0)
    path = motion_path(plan, 0.0, plan.duration, POSE_STEP)
    profile = time_path(path, 0.0, sits, _graded, ACCELERATION, longest=1.0)
    # The monitor holds it, so it waits there past the longest wait all the same, and goes
    # as soon as the monitor lets it: as monitoring alone does, so the motion is left to it.
    assert 1.0 < profile.wait <= 3.0 + STEP
    alone = reactive_profile(path, 0.0, sits, _graded, ACCELERATION)
    assert profile.arrival > alone.arrival - PAYS
    assert path_time_around(plan, 0.0, 0.0, 0.0, sits, _graded, 1.0, ACCELERATION).holds == ()
    assert SpeedCap(0.0, 1.0, 0.0, (0.5,), (0.0,)).at(-1.0) == 0.5


def test_an_unknown_timing_is_a_one_line_error():
    from hrc_drake.scenario.load import load_scenario
    from hrc_drake.scenario.schema import ScenarioError

    with pytest.raises(ScenarioError) as err:
        load_scenario("shared-desk", "{safety: {timing: sometimes}}")
    assert "safety.timing: unknown timing 'sometimes'; use wait or path_time" in str(err.value)
    assert "\n" not in str(err.value)


def test_the_shared_desk_timed_along_its_paths_keeps_separation_and_stands_on_its_way():
    """A lean shared desk (the operator who follows, seed 0) with `timing: path_time`: the
    arm stands still on its way for the hand (where no timing pays a step, the monitor stops
    it there, as it does monitoring alone), and the run's own check finds no violation."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = (
        "{safety: {separation: predictive, timing: path_time}, "
        "operator: {model: follows, seed: 0}, interaction: {mode: anticipate}}"
    )
    result = run_scenario(load_cell_scenario("shared-desk", [text, LEAN]))
    assert result.done and not result.collisions
    assert result.safety.stopped_time > 1.0
    assert result.safety.body_contacts == 0 and result.safety.violations == 0
    assert result.safety_check.beyond_permissible == 0 and result.safety_check.body_contacts == 0


def test_a_remembered_scale_answers_a_question_asked_before_without_asking_again():
    """`remembered` asks the monitor once per distinct question (pose, speed, opening, part,
    body), gives its answer again for a repeat, tells apart questions that differ in any one
    of them, and forgets the oldest past its size."""
    from hrc_drake.motion.clearance import remembered

    asked = []

    def monitor(q, qdot, opening, carrying, centres, radii, velocities) -> float:
        asked.append(1)
        return float(q[0] + qdot[0] + opening + centres.sum() + velocities.sum() + len(radii))

    scale = remembered(monitor, size=3)
    q, qdot, c, r, v = np.zeros(6), np.ones(6), np.zeros((2, 3)), np.ones(2), np.zeros((2, 3))
    first = scale(q, qdot, 0.05, None, c, r, v)
    assert scale(q, qdot, 0.05, None, c.copy(), r.copy(), v.copy()) == first
    assert len(asked) == 1
    variants = [
        (q + 0.1, qdot, 0.05, None, c, r, v),
        (q, qdot, 0.06, None, c, r, v),
        (q, qdot, 0.05, "oval_flange_1", c, r, v),
        (q, qdot, 0.05, None, c, r, v + 1.0),
    ]
    for variant in variants:
        assert scale(*variant) == monitor(*variant)
    assert len(asked) == 1 + 2 * len(variants)
    # Size 3: the first question was forgotten, so it is asked again.
    scale(q, qdot, 0.05, None, c, r, v)
    assert len(asked) == 2 + 2 * len(variants)


def _every_wait(plan, occupancy, scale, max_wait, slowing_ok, clear_only) -> float:
    """The wait of `time_around`'s search for the one motion of `plan` at time 0, each wait's
    whole delay asked (its search before it stopped asking once the answer was known)."""
    poses = motion_path(plan, 0.0, plan.duration, SAMPLE)
    best_wait, best_cost, memo = 0.0, np.inf, {}
    for wait in np.arange(0.0, max_wait + 1e-6, 0.2):
        lost = forecast_delay(poses, wait, occupancy, scale, memo)
        if lost <= 1e-6:
            if not slowing_ok or wait < best_cost - 1e-6:
                best_wait = float(wait)
            break
        if clear_only and wait > 0.0:
            continue
        cost = wait + 1.2 * lost
        if cost < best_cost - 1e-6:
            best_wait, best_cost = float(wait), cost
    return best_wait


def test_the_wait_search_stops_asking_once_the_answer_is_known_and_finds_the_same_wait():
    """`time_around` asks each wait's delay only as far as it can still matter (a clearing
    wait first, then only up to where a wait could still cost the least): on hands that leave
    the path at several times or stay beside it, with both monitors, every mode and two
    longest waits, it takes the wait that asking every wait in full takes, and asks the
    monitor less."""
    plan, asked = _plan(), {"every": 0, "search": 0}
    hands = [_sits(at=0.6, until=u) for u in (1.0, 2.5, 5.0, 8.0)]
    hands += [_blocks_then_stands_beside(u) for u in (2.0, 4.0)]
    modes = itertools.product(hands, (_graded, _stops_near), (False, True), (False, True))
    for occupancy, monitor, slowing_ok, clear_only in modes:
        for max_wait in (1.0, 6.0):
            flags = {"slowing_ok": slowing_ok, "clear_only": clear_only}

            def every(*args, monitor=monitor) -> float:
                asked["every"] += 1
                return monitor(*args)

            def search(*args, monitor=monitor) -> float:
                asked["search"] += 1
                return monitor(*args)

            wait = _every_wait(plan, occupancy, every, max_wait, **flags)
            holds = time_around(plan, 0.0, 0.0, occupancy, search, max_wait, **flags)
            assert [(h.tau, h.until) for h in holds] == ([(0.0, wait)] if wait > 0.0 else [])
    assert asked["search"] < asked["every"]
