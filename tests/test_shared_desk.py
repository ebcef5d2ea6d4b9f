"""The operator on a shared desk: the activity model, the motion layer's timing around a
forecast body, predictive separation in the cell, and the inputs it refuses."""

import subprocess
import sys

import numpy as np
import pytest
from pydrake.trajectories import PiecewisePolynomial

from hrc_drake.hri.activity import Desk, DeskBin, Person, indication_timeline, vary_person
from hrc_drake.motion.clearance import Occupancy, time_around
from hrc_drake.motion.plan import MotionTiming, Plan, Segment, Stage
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import ScenarioError

DESK = Desk(
    bins=(DeskBin("b", "bolts", (0.44, -0.22, 0.05)), DeskBin("n", "nuts", (0.47, -0.10, 0.05))),
    seats={"F1": (0.30, -0.08, 0.03)},
    parts={"F1": "F"},
    bolts={"F": 6},
)


def test_after_indicating_the_hand_points_then_fetches_bolts_then_nuts_and_rests():
    person = Person(hand_speed=1.0, handful=4, grab_time=0.5, point_time=1.0, fetch_lag=0.3)
    timeline = indication_timeline(person, DESK, "F1", indicated_at=10.0)
    stays = [m for m in timeline.moves if np.allclose(m.a, m.b) and m.end > m.start]
    assert [m.what for m in stays] == ["point", "rest", "fetch", "fetch"]
    point, lag, bolts, nuts = stays
    assert np.allclose(point.a, DESK.point("F1")) and point.end - point.start == pytest.approx(1.0)
    assert lag.end - lag.start == pytest.approx(0.3)
    # 6 bolts at 4 a handful: two grabs in each bin.
    assert np.allclose(bolts.a, DESK.bins[0].grab) and bolts.end - bolts.start == pytest.approx(1.0)
    assert np.allclose(nuts.a, DESK.bins[1].grab)
    # Each move takes the time that makes the minimum-jerk peak the hand speed.
    first = timeline.moves[0]
    distance = np.linalg.norm(first.b - first.a)
    assert first.end - first.start == pytest.approx(1.875 * distance / 1.0)
    assert np.abs(timeline.velocity(first.start + (first.end - first.start) / 2)).max() > 0
    assert np.allclose(timeline.at(timeline.end + 1.0), person.rest_hand)
    assert timeline.doing(point.start + 0.5) == "point"
    assert indication_timeline(person, DESK, "undo", 10.0).moves == ()


def test_each_operator_seed_is_its_own_person_and_the_same_seed_the_same_person():
    person = Person()
    drawn = [vary_person(person, seed, 0.3) for seed in range(8)]
    assert len({p.hand_speed for p in drawn}) == 8
    assert vary_person(person, 3, 0.3) == drawn[3]
    assert vary_person(person, 3, 0.0) == person
    for p in drawn:
        assert 0.7 * person.hand_speed <= p.hand_speed <= 1.3 * person.hand_speed


def _plan_along_x(duration: float = 4.0) -> Plan:
    """A plan whose first joint goes 0 → 1 over two motions (0–2 s: 0 → 0.5, 2–4 s: 0.5 → 1),
    each from rest to rest; the scale function below reads joint 0 as the robot's x."""
    times = np.array([0.0, 2.0, 4.0])
    knots = np.zeros((6, 3))
    knots[0] = [0.0, 0.5, 1.0]
    # Rest at every knot: cubics from rest to rest.
    pieces = [
        PiecewisePolynomial.CubicHermite(times[k : k + 2], knots[:, k : k + 2], np.zeros((6, 2)))
        for k in range(2)
    ]
    trajectory = pieces[0]
    trajectory.ConcatenateInTime(pieces[1])
    gripper = PiecewisePolynomial.ZeroOrderHold([0.0, duration], np.zeros((1, 2)))
    segments = (
        Segment(Stage.APPROACH, 0.0, 0.0),
        Segment(Stage.GRASP, 0.0, 0.0),
        Segment(Stage.CARRY, 0.0, 4.0),
    )
    motions = (MotionTiming("first", 0.0, 2.0, 2.0), MotionTiming("second", 2.0, 2.0, 2.0))
    return Plan(
        "F1", "part", frozenset(), trajectory, gripper, 4.0, 4.0, 4.0, segments, (), motions
    )


def _slows_near(q, qdot, opening, carrying, centres, radii, velocities) -> float:
    """Monitoring's stand-in: stop within 0.3 m of a body sphere, else full speed."""
    robot = np.array([q[0], 0.0, 0.0])
    return 0.0 if (np.linalg.norm(centres - robot, axis=1) - radii).min() < 0.3 else 1.0


def _reach(times, at: float, start: float, end: float) -> Occupancy:
    """A hand resting far away that reaches to x = `at` over [start, end]."""
    centres = np.array([[[at if start <= t <= end else 5.0, 0.0, 0.0]] for t in times])
    return Occupancy(times, centres, np.array([0.05]), np.zeros_like(centres))


def test_the_plan_waits_where_its_motions_meet_until_a_forecast_reach_is_over():
    plan = _plan_along_x()
    times = np.arange(0.0, 12.0, 0.1)
    reach = _reach(times, at=1.0, start=2.5, end=4.5)  # over the second motion's end
    holds = time_around(plan, 0.0, 0.0, reach, _slows_near, max_wait=6.0)
    assert len(holds) == 1
    (hold,) = holds
    assert hold.tau == pytest.approx(2.0)  # at rest between the motions, not on the way
    # It waits just long enough: the second motion then never comes near the reach.
    assert 4.5 - 2.0 <= hold.until <= 4.5 + 0.3
    # A reach the forecast puts elsewhere, or nothing forecast: no wait (reactive's plan).
    assert time_around(plan, 0.0, 0.0, _reach(times, 5.0, 2.5, 4.5), _slows_near, 6.0) == ()
    empty = Occupancy(np.zeros(0), np.zeros((0, 1, 3)), np.array([0.05]), np.zeros((0, 1, 3)))
    assert time_around(plan, 0.0, 0.0, empty, _slows_near, 6.0) == ()
    # A reach longer than the longest wait: it waits about all it may (to the forecast's
    # resolution), clear of the hand, rather than stand stopped beside it; the monitor does
    # the rest.
    long = _reach(times, at=1.0, start=2.5, end=11.0)
    (hold,) = time_around(plan, 0.0, 0.0, long, _slows_near, max_wait=1.0)
    assert hold.tau == pytest.approx(2.0) and 2.6 <= hold.until <= 3.0 + 1e-9
    # Having waited there already, it waits no longer than the rest of the longest wait.
    (hold,) = time_around(plan, 0.0, 0.0, long, _slows_near, max_wait=1.0, spent=(2.0, 0.6))
    assert hold.until <= 2.4 + 1e-9


def test_beside_a_hand_that_only_goes_away_the_plan_may_be_slowed_rather_than_wait():
    """With `slowing_ok` (the hand seen in the last bin of its fetch), a wait that would cost
    more than being slowed past the hand is not taken: here the reach only halves the speed."""
    plan = _plan_along_x()
    times = np.arange(0.0, 12.0, 0.1)
    reach = _reach(times, at=1.0, start=0.0, end=5.0)

    def halves_near(q, qdot, opening, carrying, centres, radii, velocities) -> float:
        return (
            0.5 if _slows_near(q, qdot, opening, carrying, centres, radii, velocities) < 1 else 1.0
        )

    (hold,) = time_around(plan, 0.0, 0.0, reach, halves_near, max_wait=6.0)
    assert hold.tau == pytest.approx(2.0) and hold.until >= 4.0  # waits out the reach
    assert time_around(plan, 0.0, 0.0, reach, halves_near, 6.0, slowing_ok=True) == ()
    # A reach that would stop the arm is still waited out.
    (hold,) = time_around(plan, 0.0, 0.0, reach, _slows_near, 6.0, slowing_ok=True)
    assert hold.until >= 4.0


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("{safety: {separation: sometimes}}", "safety.separation: unknown mode 'sometimes'"),
        ("{body: {hand_speed: 0}}", "body.hand_speed"),
        ("{body: {hand_speed: -1}}", "body.hand_speed"),
        ("{body: {activity: juggling}}", "body.activity"),
        (
            "{cell: {bins: [{name: far, holds: nuts, position: [0.1, 0.45]}]}}",
            "out of the operator's right hand's reach",
        ),
        (
            "{cell: {bins: [{name: base, holds: nuts, position: [0.05, 0.02]}]}}",
            "inside the robot's footprint",
        ),
        ("{cell: {bins: [{name: x, holds: screws, position: [0.5, 0.0]}]}}", "holds"),
        ("{safety: {forecast_spread: -0.5}}", "safety.forecast_spread: give a fraction"),
        ("{safety: {forecast_spread: 2}}", "safety.forecast_spread: give a fraction"),
    ],
)
def test_bad_desk_inputs_are_one_line_errors(text, needle):
    with pytest.raises(ScenarioError, match=None) as err:
        load_scenario("shared-desk", text)
    assert needle in str(err.value)
    assert "\n" not in str(err.value)


def test_separation_flag_is_checked_before_any_work():
    cmd = [sys.executable, "-m", "hrc_drake.cli", "simulate", "--separation", "maybe", "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "hrc-drake simulate: error: --separation: unknown mode 'maybe'; use predictive or reactive"
    ]


def test_a_body_the_forecast_cannot_explain_replaces_every_forecast_timeline_while_it_stays():
    """Each timeline of a joined forecast (whole body first, then arms) is replaced by the
    observed body's same spheres until the stay ends, and left as forecast after it."""
    from hrc_drake.cell.controller.forecast import Anchor, OperatorForecast
    from hrc_drake.cell.controller.keep_clear import _staying
    from hrc_drake.cell.person import body_pose
    from hrc_drake.cell.ports import BodySpheres

    person = Person()
    forecast = OperatorForecast(person, DESK, delay=1.0, sigma=0.3)
    offsets = forecast.offsets(True)
    occupancy = forecast.occupancy(Anchor("F1", 0.0), 0.0, 3.0, offsets)
    pose = body_pose(np.asarray(person.stance), np.array([0.35, 0.0, 0.25]))
    centres, radii, groups = pose.spheres()
    body = BodySpheres(centres, radii, np.zeros_like(centres), groups)
    held = _staying(occupancy, body, until=1.0)
    n, arm = len(radii), groups[2][1]
    assert occupancy.centres.shape[1] == n + arm * (len(offsets) - 1)
    early, late = occupancy.times <= 1.0, occupancy.times > 1.0
    for start in [0, *range(n, occupancy.centres.shape[1], arm)]:
        size = n if start == 0 else arm
        assert np.allclose(held.centres[early, start : start + size], centres[:size])
    assert not np.allclose(occupancy.centres[early], held.centres[early])
    assert np.array_equal(held.centres[late], occupancy.centres[late])


def test_a_forecast_without_timing_spread_is_the_one_timeline_of_the_model():
    """`safety.forecast_spread` 0 keeps only the modelled timeline (the bound of a perfect
    forecast); 1 keeps the whole spread, before the indication (delay quantiles), after it and
    once seen."""
    from hrc_drake.cell.controller.forecast import Anchor, OperatorForecast

    person = Person()
    full = OperatorForecast(person, DESK, delay=2.0, sigma=0.4)
    exact = OperatorForecast(person, DESK, delay=2.0, sigma=0.4, spread=0.0)
    for stage in (False, True, "seen"):
        assert exact.offsets(stage) == (0.0,)
        assert len(full.offsets(stage)) >= 3
    assert min(full.offsets(False)) < 0.0 < max(full.offsets(False))
    assert full.offsets(True)[0] == pytest.approx(-OperatorForecast.EARLY)
    # Half the spread: the same timelines, half as far from the model's.
    half = OperatorForecast(person, DESK, delay=2.0, sigma=0.4, spread=0.5)
    assert np.allclose(half.offsets(True), np.asarray(full.offsets(True)) / 2)
    anchor = Anchor("F1", 0.0)
    one = exact.occupancy(anchor, 0.0, 2.0, exact.offsets(True))
    joined = full.occupancy(anchor, 0.0, 2.0, full.offsets(True))
    assert one.centres.shape[1] < joined.centres.shape[1]
    # The fitted forecast keeps its spread.
    from hrc_drake.cell.person import body_pose
    from hrc_drake.cell.ports import BodySpheres

    centres, radii, groups = body_pose(
        np.asarray(person.stance), np.asarray(person.rest_hand)
    ).spheres()
    fitted = exact.fitted(BodySpheres(centres, radii, np.zeros_like(centres), groups))
    assert fitted.offsets(True) == (0.0,)


# --- predictive separation in the cell (lean holds) -------------------------------------------

DESK_TEXT = "{operator: {model: follows, seed: 0}, body: {spread: 0.0}, interaction: {mode: wait}}"


def _desk_run(separation: str, **person):
    """A lean run of the shared desk; `person`: how the simulated operator differs from the
    one the scenario describes (and the controller forecasts)."""
    from dataclasses import replace

    from hrc_drake.cell.person import desk_of
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario
    from hrc_drake.cell.station.desk import DeskScript
    from hrc_drake.motion.scene import load_cell_frames
    from hrc_drake.tasks.spec import load_spec

    texts = [DESK_TEXT, LEAN, f"{{safety: {{separation: {separation}}}}}"]
    scenario = load_cell_scenario("shared-desk", texts)
    script = None
    if person:
        design = cell_design(scenario, load_spec(scenario.assembly_path))
        desk = desk_of(load_cell_frames(design), design.layout)
        script = DeskScript(replace(scenario.body.person(), **person), desk)
    return run_scenario(scenario, body_script=script)


@pytest.fixture(scope="module")
def desk_runs():
    """The shared desk with the forecast's own person, monitoring alone and predictive."""
    return {mode: _desk_run(mode) for mode in ("reactive", "predictive")}


def test_both_separation_modes_keep_s_p_by_the_runs_check_and_predictive_plans_waits(desk_runs):
    """Monitoring alone and predictive both keep the protective separation by the run's own
    check (this person never comes inside it, not even at the contact speed) and never touch.
    The controller's monitor slows the plan so that the station's safety function need not stop
    it: no stop of either kind (monitoring alone made 13 safeguard stops, and 6 violations,
    while its creep past the fetching hand allowed for no lag between its limit and the arm).
    Predictive also plans waits at rest points; monitoring alone never does."""
    reactive, predictive = desk_runs["reactive"], desk_runs["predictive"]
    for result in (reactive, predictive):
        assert result.done and not result.collisions
        assert result.names == ["1", "2", "7", "10"]
        assert result.safety_check.violations == 0 and result.safety_check.body_contacts == 0
        assert result.safety.body_contacts == 0
        function = result.safety_function
        assert function.safeguard_stops == 0 and function.protective_stops == 0
    assert reactive.waited == 0.0 and predictive.waited > 0.0
    assert predictive.to_json()["separation"] == "predictive"
    assert predictive.to_json()["safety"]["monitor"]["ssm_delay"] == pytest.approx(
        predictive.safety.ssm_delay, abs=1e-3
    )
    assert predictive.to_json()["safety"]["function"]["protective_stops"] == 0


def test_with_an_exact_forecast_path_timing_is_never_slower_than_monitoring_alone(desk_runs):
    """The forecast's own person, forecast without timing spread: the path timing commits
    only where it arrives a step before monitoring alone against that forecast, so the run is
    no slower than monitoring alone's (before that rule it stood back for the hand at the nut
    bin, and took 38.77 s against 38.63 s)."""
    timed = _desk_run("predictive, timing: path_time, forecast_spread: 0.0")
    alone = desk_runs["reactive"]
    assert timed.done and timed.names == alone.names
    assert timed.safety_check.violations == 0 and timed.safety_check.body_contacts == 0
    assert timed.sim_time <= alone.sim_time + 1e-9


def test_a_person_unlike_the_forecast_makes_the_robot_retime_and_keeps_separation():
    # This operator dawdles 2.5 s before fetching and grabs twice as long: the forecast, made
    # for the population's person, is wrong until the tracker shows where they are.
    result = _desk_run("predictive", fetch_lag=2.5, grab_time=2.0)
    assert result.done and not result.collisions
    assert result.replans > 0
    assert result.safety.body_contacts == 0
    assert result.safety_check.beyond_permissible == 0 and result.safety_check.body_contacts == 0


def test_a_part_put_back_is_timed_around_the_operator_too():
    """A swap: the habitual operator indicates S23 while the robot carries F1, which it puts
    back, retreating while the operator goes for the bolts. The put-back plan holds for no
    bolts, so it is timed to its end (it was timed only to its release: 9 violations)."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = "{operator: {model: habitual, seed: 3}}"
    result = run_scenario(load_cell_scenario("shared-desk", [text, LEAN]))
    assert result.done and result.tasks[0].swapped
    assert result.safety.body_contacts == 0
    # By the run's own check (timed only to its release: 9 violations).
    assert result.safety_check.beyond_permissible == 0 and result.safety_check.body_contacts == 0


def test_the_robot_keeps_clear_of_the_desks_bins_in_every_placement_plan():
    """The bins are drawn, not in the robot's plant: the layout keeps them clear. Every
    placement plan of the flange case keeps the arm, its fingers as commanded and the part it
    carries at least 1 cm from every point of the bins' tops."""
    from hrc_drake.cell.robot_envelope import RobotEnvelope, nearest_points
    from hrc_drake.cell.run.run import shared_planner
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec
    from hrc_drake.tasks.tokens import UNDO

    scenario = load_cell_scenario("shared-desk", None)
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    planner = shared_planner(motion_options(scenario), design)
    envelope, space = RobotEnvelope(design), generate_states(design.spec)
    tops = np.array(
        [
            [x, y, b.size[2]]
            for b in scenario.cell.bins
            for x in np.linspace(b.position[0] - b.size[0] / 2, b.position[0] + b.size[0] / 2, 7)
            for y in np.linspace(b.position[1] - b.size[1] / 2, b.position[1] + b.size[1] / 2, 7)
        ]
    )
    closest, plans = np.inf, 0
    for index in range(space.n_states):
        for task, _ in space.tasks(index):
            if task == UNDO:
                continue
            plan = planner.plan_task(frozenset(space.configuration(index)), task)
            plans += 1
            for tau in np.linspace(0.0, plan.duration, 80):
                shapes = envelope.shapes(plan.carrying(tau), True)
                R, p = envelope.pose(plan.positions(tau), plan.gripper_opening(tau))
                closest = min(closest, nearest_points(shapes, R, p, tops).distance.min())
    assert plans == 19
    assert closest >= 0.01, closest


@pytest.mark.parametrize("contact_speed, clear_only", [(0.0, True), (0.25, False)])
def test_with_separation_alone_predictive_waits_only_where_a_wait_clears_the_motion(
    contact_speed, clear_only
):
    """`safety.contact_speed: 0` (the monitor keeps S_p by itself) makes predictive separation
    take only the waits that clear a motion (`KeepClearSettings.clear_only`)."""
    from hrc_drake.cell.controller.build import keep_clear_settings
    from hrc_drake.cell.robot_envelope import RobotEnvelope
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.tasks.spec import load_spec

    text = f"{{safety: {{contact_speed: {contact_speed}}}}}"
    scenario = load_cell_scenario("shared-desk", [text])
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    settings = keep_clear_settings(
        scenario, design, RobotEnvelope(design), motion_options(scenario)
    )
    assert settings.forecast is not None and settings.clear_only is clear_only


@pytest.mark.slow
def test_a_person_standing_still_beside_the_path_does_not_hold_the_robot_forever():
    """Separation alone at ISO 13855's constant speed: the habitual operator waits at the desk
    while the robot carries the second part past them, and the carry comes within the monitor's
    slow band of S_p from their torso. The arm creeps on there as fast as keeps S_p, instead of
    standing for as long as the person does (before, it stood from 68 s to the run's 900 s
    cap), and the run keeps S_p by its own check."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    texts = [
        "{operator: {model: habitual, seed: 0}, interaction: {mode: anticipate}}",
        "{safety: {separation: reactive, human_speed: constant, contact_speed: 0.0}}",
        "{body: {rest_hand: [0.9, 0.10, 0.06]}}",
        LEAN,
    ]
    result = run_scenario(load_cell_scenario("shared-desk", texts))
    assert result.done and not result.collisions
    assert result.sim_time < 200.0
    assert result.safety_check.violations == 0 and result.safety_check.body_contacts == 0


def _forecast_monitor():
    """(settings, envelope, options, scenario) of `shared-desk`'s predictive separation."""
    from hrc_drake.cell.controller.build import keep_clear_settings
    from hrc_drake.cell.robot_envelope import RobotEnvelope
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.tasks.spec import load_spec

    scenario = load_cell_scenario("shared-desk", None)
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    envelope, options = RobotEnvelope(design), motion_options(scenario)
    return keep_clear_settings(scenario, design, envelope, options), envelope, options, scenario


def _monitor_limit(envelope, options, scenario, q, qdot, body) -> float:
    """The controller's monitor's limit for the arm at `q`, `qdot` (opening 5 cm) by `body`."""
    from hrc_drake.cell.controller.intent import MotionIntent
    from hrc_drake.cell.controller.separation import MONITOR_LAG, assess

    period = scenario.run.period
    intent = MotionIntent(qdot=qdot, carrying=None, moving=True, rate=1.0)
    acceleration = options.joint_acceleration_limit
    lag = MONITOR_LAG * period
    return assess(
        envelope, q, qdot, body, intent, scenario.safety, acceleration, 0.05, period, lag
    ).limit


def test_the_forecast_monitor_asks_about_each_repeated_sphere_once_with_the_same_scale():
    """A joined forecast repeats the spheres its timelines share (the hand resting in one
    place): `distinct_spheres` keeps each once, in order, and keeps spheres that differ in their
    velocity alone; the forecast monitor's scale over a joined forecast's samples equals the
    monitor's whole assessment of every sphere, the body's parts told."""
    from hrc_drake.cell.controller.forecast import Anchor, distinct_spheres
    from hrc_drake.cell.person import BODY_GROUPS
    from hrc_drake.cell.ports import BodySpheres

    centres = np.array([[0.4, 0.1, 0.2], [0.4, 0.1, 0.2], [0.5, 0.0, 0.2], [0.4, 0.1, 0.2]])
    velocities = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    kept = distinct_spheres(centres, np.full(4, 0.05), velocities)
    assert np.array_equal(kept[0], centres[[0, 2, 3]])
    assert np.array_equal(kept[2], velocities[[0, 2, 3]])

    settings, envelope, options, scenario = _forecast_monitor()
    forecast = settings.forecast
    occupancy = forecast.occupancy(Anchor("F1", 0.0), 0.0, 6.0, forecast.offsets(False))
    # A pose and a speed that the forecast limits on some samples (found by a random search).
    q = np.array([-2.34, 1.38, -2.21, -0.75, -0.44, -0.07])
    qdot = np.array([0.31, -0.18, -0.32, -0.14, 1.09, -0.03])
    repeated, scales = 0, []
    for i in range(len(occupancy.times)):
        c, r, v = occupancy.centres[i], occupancy.radii, occupancy.velocities[i]
        repeated += len(r) - len(distinct_spheres(c, r, v)[1])
        whole = BodySpheres(c, r, v, BODY_GROUPS)
        scales.append(settings.scale(q, qdot, 0.05, None, c, r, v))
        assert scales[-1] == _monitor_limit(envelope, options, scenario, q, qdot, whole)
    assert repeated > 0
    assert min(scales) < 1.0 == max(scales)


def test_the_forecast_monitor_permits_no_approach_to_the_forecast_head():
    """The monitor lets the arm creep toward a hand at the contact speed, never toward the
    head (ISO/TS 15066 Annex A). The forecast monitor reads a forecast body's head as the
    head: an arm coming down slowly onto it is stopped, where the same spheres without their
    parts (all touchable) would let it creep."""
    from hrc_drake.cell.person import BODY_GROUPS, body_pose
    from hrc_drake.cell.ports import BodySpheres

    settings, envelope, options, scenario = _forecast_monitor()
    q = np.array([0.0, -1.2, 1.4, -1.8, -1.57, 0.0])
    qdot = np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0])  # the shoulder lifts: the tool comes down
    tool = envelope.pose(q, 0.05)[1][-1]
    centres, radii, groups = body_pose(np.zeros(2), np.array([0.3, 0.3, 0.3])).spheres()
    head = centres[groups[-1][0]]
    centres = centres + (tool - head) - np.array([0.0, 0.0, 0.2])  # the head under the tool
    velocities = np.zeros_like(centres)
    assert groups == BODY_GROUPS
    limit = settings.scale(q, qdot, 0.05, None, centres, radii, velocities)
    parts = BodySpheres(centres, radii, velocities, groups)
    none = BodySpheres(centres, radii, velocities)
    assert limit == _monitor_limit(envelope, options, scenario, q, qdot, parts) == 0.0
    assert _monitor_limit(envelope, options, scenario, q, qdot, none) > 0.0
