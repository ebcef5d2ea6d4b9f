"""The guarded descent's trigger on synthetic wrist loads (`hrc_drake.cell.controller.guard`):
it trips on a rim met before the seat, not on a seat taking the part's weight, not at the seat
itself, not on a realistic sensor's noise."""

import numpy as np
import pytest
from pydrake.trajectories import PiecewisePolynomial

from hrc_drake.cell.controller.guard import (
    ZERO_READINGS,
    DescentGuard,
    GuardSettings,
    GuardState,
    Retreat,
    height_above_place,
)
from hrc_drake.motion.plan import Plan, Segment, Stage

DESCENT = 0.06  # m, the place's straight descent
PERIOD = 0.02  # s, the Supervisor's update
WEIGHT = 5.6  # N, the square flange hanging in the fingers
Q_TOP = np.array([0.1, -1.2, 1.5, -1.9, -1.57, 0.3])
Q_SEAT = Q_TOP + np.array([0.0, 0.05, -0.08, 0.03, 0.0, 0.0])


def _plan() -> Plan:
    """A plan whose place stage is a 1 s descent from Q_TOP to Q_SEAT, the joints moving in
    proportion (the guard's reading of the height is then exact)."""
    knots = np.column_stack([Q_TOP, Q_TOP, Q_SEAT, Q_SEAT])
    trajectory = PiecewisePolynomial.FirstOrderHold([0.0, 1.0, 2.0, 3.0], knots)
    stages = (Stage.CARRY, Stage.PLACE, Stage.HOLD)
    return Plan(
        task="S12",
        instance="square_flange",
        configuration=frozenset(),
        trajectory=trajectory,
        gripper=PiecewisePolynomial(np.array([[0.088]])),
        t_in_place=2.0,
        t_release=3.0,
        duration=3.0,
        segments=tuple(Segment(s, float(i), float(i + 1)) for i, s in enumerate(stages)),
        phases=(),
        motions=(),
        grip_width=0.09,
    )


def _descend(loads, settings: GuardSettings | None = None, plan_start=0.0):
    """Feed `loads(tau, height)` (upward force [N], or None: no reading) along the descent at
    the Supervisor's rate; the guard's last state and its trip (or None)."""
    plan, guard, state = _plan(), DescentGuard(settings or GuardSettings()), GuardState()
    for tau in np.arange(1.0, 2.0, PERIOD):
        q = plan.positions(tau)
        height = height_above_place(plan, q, DESCENT)
        load = loads(tau, height)
        wrench = None if load is None else np.array([0.0, 0.0, load, 0.0, 0.0, 0.0])
        state, trip = guard.watch(state, plan, plan_start, tau, q, wrench)
        if trip is not None:
            return state, trip, tau
    return state, None, None


def test_the_back_off_commands_the_velocity_of_its_own_path():
    """The retreat up the descent gives the servo its velocity (the derivative of its
    positions), zero while it holds and after it ends: a zero velocity command had the servo's
    damping drag the arm 0.048 rad behind, and the tracking check stop the recovery."""
    plan = _plan()
    retreat = Retreat(plan, tuple(plan.positions(1.6)), 1.6, 1.0, start=5.0, end=5.9)
    step = 1e-5
    for now in (5.1, 5.45, 5.8):
        numeric = (retreat.positions(now + step) - retreat.positions(now - step)) / (2 * step)
        np.testing.assert_allclose(retreat.velocities(now), numeric, atol=1e-6)
    # Midway, 1.5x its mean speed: 0.6 plan-s of a 0.099 rad/s descent over 0.9 s.
    assert np.linalg.norm(retreat.velocities(5.45)) == pytest.approx(0.099, rel=0.01)
    for now in (4.0, 6.0):
        np.testing.assert_array_equal(retreat.velocities(now), np.zeros(6))


def test_the_height_above_the_place_is_read_from_the_plan():
    plan = _plan()
    assert height_above_place(plan, Q_TOP, DESCENT) == pytest.approx(DESCENT)
    assert height_above_place(plan, plan.positions(1.75), DESCENT) == pytest.approx(0.015)
    assert height_above_place(plan, Q_SEAT, DESCENT) == pytest.approx(0.0)


def test_a_rim_met_before_the_seat_trips_the_guard_and_it_backs_off_to_before_the_contact():
    # The part hangs (its weight down) until it meets a rim 3.5 mm above its seat; then the rim
    # pushes back, 40 N at once, as measured at either modulus.
    def rim(tau, height):
        return -WEIGHT if height > 0.0035 else 40.0 - WEIGHT

    state, trip, _ = _descend(rim)
    assert trip is not None
    assert trip.rise == pytest.approx(40.0)
    assert 0.0035 - DESCENT * PERIOD < trip.above <= 0.0035
    # Backs off to where it stood at the last reading before the contact, above the rim.
    back = height_above_place(_plan(), np.array(trip.q_back), DESCENT)
    assert 0.0035 < back <= 0.0035 + DESCENT * PERIOD + 1e-9
    assert state.zero == pytest.approx(-WEIGHT)


def test_a_small_rise_past_the_threshold_trips_and_one_under_it_does_not():
    def pressing(rise):
        return lambda tau, height: -WEIGHT + (rise if height < 0.003 else 0.0)

    assert _descend(pressing(8.5))[1] is not None
    assert _descend(pressing(7.5))[1] is None
    # The threshold is the scenario's: 20 N lets a 15 N rise by.
    assert _descend(pressing(15.0), GuardSettings(threshold=20.0))[1] is None


def test_a_seat_taking_the_weight_and_a_jolt_at_the_seat_itself_do_not_trip_it():
    # The seat takes the whole weight off the fingers in the last 2 mm (the load rises by the
    # weight), then, within the last 0.1 mm, a contact jolt of 22 N (measured on a re-placed
    # square flange): the guard is disarmed there, where the part meets its own seat.
    def seat(tau, height):
        if height < 0.0001:
            return 22.0 - WEIGHT
        return -WEIGHT * min(1.0, height / 0.002)

    state, trip, _ = _descend(seat)
    assert trip is None
    assert state.peak < 8.0


def test_a_realistic_sensors_noise_does_not_trip_it():
    # 1 N of noise on every reading (`sensors: realistic`), the seat taking the weight: the
    # mean of the first readings zeroes the guard well enough for 8 N.
    rng = np.random.default_rng(7)
    for _ in range(50):
        noisy = lambda tau, height: -WEIGHT * min(1.0, height / 0.002) + rng.normal(0.0, 1.0)  # noqa: E731
        assert _descend(noisy)[1] is None


def test_without_a_reading_or_disabled_it_never_trips_and_a_new_plan_starts_it_afresh():
    def rim(tau, height):
        return -WEIGHT if height > 0.0035 else 40.0

    assert _descend(lambda tau, height: None)[1] is None
    assert _descend(rim, GuardSettings(enabled=False))[1] is None
    plan, guard = _plan(), DescentGuard(GuardSettings())
    state = GuardState()
    for k in range(ZERO_READINGS):
        tau = 1.0 + k * PERIOD
        wrench = np.array([0.0, 0.0, -WEIGHT, 0.0, 0.0, 0.0])
        state, _ = guard.watch(state, plan, 0.0, tau, plan.positions(tau), wrench)
    assert state.zero == pytest.approx(-WEIGHT)
    # Outside the descent it reads nothing; a plan started later starts from nothing.
    state, trip = guard.watch(state, plan, 0.0, 2.5, Q_SEAT, np.array([0, 0, 99.0, 0, 0, 0]))
    assert trip is None and state.zero == pytest.approx(-WEIGHT)
    state, _ = guard.watch(state, plan, 5.0, 1.0, Q_TOP, np.array([0, 0, -1.0, 0, 0, 0]))
    assert state.plan_start == 5.0 and state.readings == (-1.0,) and state.zero is None


@pytest.mark.parametrize("value", ["-1", ".nan", ".inf"])
def test_a_guard_force_no_sensor_can_read_is_refused_in_one_line(value):
    from hrc_drake.scenario.load import load_scenario
    from hrc_drake.scenario.schema import ScenarioError

    problem = r"run\.place_guard: (give newtons >= 0|.*finite)"
    with pytest.raises(ScenarioError, match=problem) as err:
        load_scenario("row1-optimal", f"{{run: {{place_guard: {value}}}}}")
    assert "\n" not in str(err.value)
    assert load_scenario("row1-optimal", "{run: {place_guard: 0}}").run.place_guard == 0.0
