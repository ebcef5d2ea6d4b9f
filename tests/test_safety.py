"""The operator's body in the cell and speed and separation monitoring (ISO/TS 15066 §5.5.4)."""

import dataclasses

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.separation import (
    BAND_CREEP,
    STAND_BEFORE_CREEP,
    STILL_SPEED,
    BandCreep,
    BodyAge,
    ControllerSeparationMonitor,
    SafetyLog,
    SeparationReading,
    assess,
    band_creep_step,
    log_step,
    planned_distance,
    planned_scales,
)
from hrc_drake.cell.person import CHAIN_GAP, body_pose
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope, nearest_points
from hrc_drake.cell.run.run import run_scenario, shared_planner
from hrc_drake.cell.scenario import LEAN, load_cell_scenario, motion_options
from hrc_drake.cell.ssm import NEAR_SPEED, allowed_scale
from hrc_drake.cell.station.build import make_cell_station, station_scenario
from hrc_drake.cell.station.operator_body import ReachInto
from hrc_drake.motion.plan import Stage
from hrc_drake.motion.poses import part_pose
from hrc_drake.robot_models import set_rg2_opening
from hrc_drake.scenario.safety import HumanSpeed, SafetyConfig
from hrc_drake.scenario.schema import BodyConfig, Scenario, ScenarioError


def test_allowed_scale_is_the_largest_speed_that_keeps_the_separation():
    # S_p(s) = 0.1 + 0.2 s + 0.1 s^2 against a gap of 0.25: s = (-0.2 + sqrt(0.1)) / 0.2.
    s = allowed_scale(np.array([0.25]), np.array([0.1]), np.array([0.2]), np.array([0.1]))
    assert s == pytest.approx((-0.2 + np.sqrt(0.04 + 0.06)) / 0.2)
    assert 0.1 + 0.2 * s + 0.1 * s * s == pytest.approx(0.25)
    assert allowed_scale(np.array([1.0]), np.array([0.1]), np.array([0.2]), np.array([0.1])) == 1
    assert allowed_scale(np.array([0.05]), np.array([0.1]), np.array([0.2]), np.array([0.0])) == 0


def test_the_arm_is_two_links_of_fixed_length_from_the_shoulder_to_the_hand():
    stance = np.array([0.9, 0.0])
    near = body_pose(stance, np.array([0.6, 0.1, 0.1]))
    assert np.linalg.norm(near.elbow - near.shoulder) == pytest.approx(0.30)
    assert np.linalg.norm(near.hand - near.elbow) == pytest.approx(0.32)
    # Too far for the arm: the torso leans in and the arm still reaches.
    far = body_pose(stance, np.array([0.25, 0.0, 0.05]))
    assert far.torso[0] < near.torso[0]
    assert np.linalg.norm(far.hand - far.shoulder) <= 0.62 + 1e-9


def test_bad_body_values_are_refused():
    with pytest.raises(ScenarioError, match=r"body\.hand_speed"):
        load_cell_scenario("row1-optimal", "{body: {hand_speed: 3.0}}")
    with pytest.raises(ScenarioError, match=r"body\.stance"):
        load_cell_scenario("row1-optimal", "{body: {stance: [1.0]}}")


@pytest.mark.slow
def test_a_hand_in_the_robots_path_slows_then_stops_it_and_it_resumes():
    """Mid-carry the operator's hand moves above the seat the robot is heading for, stays 2 s
    and goes back: the robot slows, stops short of it, never moves with less than S_p, then
    resumes and finishes the run as without the hand."""
    # The hand is scripted against the robot's timing when it waits for each indication.
    scenario = load_cell_scenario("row1-optimal", [LEAN, "{interaction: {mode: wait}}"])
    frames = make_cell_station(station_scenario(scenario, robot=False)).frames
    above_seat = part_pose(frames, "F1", []).translation() + np.array([0.0, 0.0, 0.12])
    # The plan of step 1 starts as the operator indicates F1 (simulated time stands still while
    # it is planned): the hand sets off 0.2 s into its carry.
    plan = shared_planner(motion_options(scenario)).plan_task(frozenset(), "F1")
    delay = plan.segment(Stage.CARRY).start + 0.2
    hand = ReachInto(BodyConfig().rest_hand, above_seat, step=1, delay=delay, dwell=2.0)
    result = run_scenario(scenario, body_script=hand)
    assert hand.start is not None
    assert result.error is None and result.done
    assert result.names == list(scenario.minimum_effort) and result.collisions == []
    safety = result.safety
    assert safety.body_contacts == 0
    # By the run's own check too: the hand that set off toward the carry was allowed for.
    assert result.safety_check.beyond_permissible == 0 and result.safety_check.body_contacts == 0
    assert safety.slowed_time > 0 and safety.stopped_time > 0
    assert 0 < safety.min_separation < 0.2
    states = [state for _, state in result.speed_changes]
    first_stop = states.index("stopped")
    assert "slowed" in states[:first_stop], states
    assert states[-1] == "moving" and "moving" in states[first_stop:]
    # The robot waited for the hand: the first task took longer than the hand stayed.
    times = dict((s, t) for t, s in reversed(result.speed_changes))
    assert times["stopped"] >= hand.start
    data = result.to_json()["safety"]
    assert set(data) == {"summary", "check", "function", "monitor"}
    assert set(data["monitor"]) >= {"min_separation", "min_margin", "violations", "slowed_time"}


def test_a_run_without_the_body_reports_no_separation():
    """With the operator's body off there is no separation to monitor: the run's `safety` is
    None, in its JSON too. (Every Table 2 row runs with the body and no violation in
    tests/test_closed_loop.py.)"""
    short = "{body: {enabled: false}, run: {max_sim_time: 1.0}}"
    off = run_scenario("row7-forces-9", scenario_text=[LEAN, short])
    assert off.safety is None and off.to_json()["safety"] is None


# The controller's separation monitor (hrc_drake.cell.controller.separation): its own model of the
# robot (hrc_drake.cell.robot_envelope), measured inputs only.

POSTURES = (
    (0.0, -1.57, 1.2, -1.2, -1.57, 0.0),
    (0.6, -1.0, 1.6, -2.2, -1.2, 0.8),
    (-1.2, -2.0, 0.7, -0.3, 1.4, -2.0),
    (2.5, -0.6, -1.9, 1.0, 0.4, 3.0),
    (-0.4, -1.3, 2.2, 0.9, -2.6, 1.1),
)
SPHERE = 0.04  # m, the radius of the probe spheres (an arm link's)


@pytest.fixture(scope="module")
def cell():
    """The full cell (Drake's exact geometry) and the controller's envelope of the same design."""
    station = make_cell_station(Scenario())
    return station, RobotEnvelope(station.design)


def _robot_geometry(station, carrying):
    plant = station.plant
    models = [station.instances["ur3"], station.instances["rg2"]]
    if carrying is not None:
        models.append(station.instances[carrying])
    return {
        gid
        for model in models
        for index in plant.GetBodyIndices(model)
        for gid in plant.GetCollisionGeometriesForBody(plant.get_body(index))
    }


def _exact_separations(station, q, opening, carrying, centres):
    """Drake's signed distance from each centre to the robot (and the part it holds at its
    grasp), less the probe's radius as the monitor counts it."""
    plant, scene_graph = station.plant, station.scene_graph
    root = station.diagram.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(root)
    plant.SetPositions(context, station.instances["ur3"], q)
    set_rg2_opening(plant, context, opening)
    if carrying is not None:
        X_W_tcp = plant.GetFrameByName("tcp").CalcPoseInWorld(context)
        body = plant.get_body(plant.GetBodyIndices(station.instances[carrying])[0])
        plant.SetFreeBodyPose(context, body, X_W_tcp @ station.frames.grasps[carrying].inverse())
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root))
    robot = _robot_geometry(station, carrying)
    distance = [
        min(d.distance for d in query.ComputeSignedDistanceToPoint(c, 10.0) if d.id_G in robot)
        for c in centres
    ]
    return np.array(distance) - SPHERE * (1 + CHAIN_GAP), context


def _probes(station, context, rng, count=12):
    """Sphere centres within 0.15 m of each robot body's origin."""
    plant = station.plant
    origins = [
        plant.get_body(index).EvalPoseInWorld(context).translation()
        for model in (station.instances["ur3"], station.instances["rg2"])
        for index in plant.GetBodyIndices(model)
    ]
    return np.vstack([o + rng.uniform(-0.15, 0.15, (count, 3)) for o in origins])


def _one_sphere(centre, velocity=(0.0, 0.0, 0.0), radius=SPHERE):
    return BodySpheres(
        np.array([centre], dtype=float), np.array([radius]), np.array([velocity], dtype=float)
    )


def _separations(envelope, q, opening, carrying, centres):
    intent = MotionIntent(carrying=carrying)
    return np.array(
        [
            assess(
                envelope, q, np.zeros(6), _one_sphere(c), intent, SafetyConfig(), 3.0, opening
            ).separation
            for c in centres
        ]
    )


@pytest.mark.parametrize("carrying", [None, "oval_flange_1", "square_flange"])
def test_the_monitors_envelope_is_never_farther_than_drakes_exact_distance(cell, carrying):
    """Spheres around the robot at five postures: the monitor's separation is Drake's signed
    distance (ComputeSignedDistanceToPoint on the full cell) within 1 µm, never more; the
    robot's shapes (and the held part's) are boxes, cylinders and capsules, which the envelope
    keeps exactly."""
    station, envelope = cell
    rng = np.random.default_rng(7)
    checked = 0
    for q in POSTURES:
        opening = rng.uniform(0.0, 0.11)
        _, context = _exact_separations(station, q, opening, carrying, [])
        centres = _probes(station, context, rng)
        exact, _ = _exact_separations(station, q, opening, carrying, centres)
        mine = _separations(envelope, np.array(q), opening, carrying, centres)
        assert np.all(mine <= exact + 1e-9)
        assert np.max(exact - mine) < 1e-6
        checked += int(np.sum(exact < 0.05))
    assert checked > 20  # many probes were close to (or inside) the robot


def test_fingers_whose_opening_is_not_measured_count_over_their_whole_travel(cell):
    """Without `rg2.state_measured` the monitor takes the box each finger sweeps: never farther
    than the fingers at any opening, at most the travel (55 mm) nearer than the nearest of them,
    and nearer than the fingers at the opening that holds an oval flange (45 mm)."""
    station, envelope = cell
    rng = np.random.default_rng(3)
    q = np.array(POSTURES[1])
    _, context = _exact_separations(station, q, 0.0, None, [])
    tcp = station.plant.GetFrameByName("tcp").CalcPoseInWorld(context).translation()
    centres = tcp + rng.uniform(-0.15, 0.15, (60, 3))
    exact = {
        opening: _exact_separations(station, q, opening, None, centres)[0]
        for opening in (0.0, 0.045, 0.08, 0.11)
    }
    nearest = np.min(list(exact.values()), axis=0)
    swept = _separations(envelope, q, None, None, centres)
    assert np.all(swept <= nearest + 1e-9)
    assert np.all(nearest - swept <= 0.055 + 1e-9)
    assert np.max(exact[0.045] - swept) > 0.01  # the sweep is felt beside the fingers


def test_the_monitors_point_velocities_are_drakes(cell):
    """Every robot shape's nearest point moves, by the envelope's link velocities, as Drake's
    translational velocity Jacobian at that point says (measured v and the plan's q̇ alike)."""
    _, envelope = cell
    plant, context = envelope.plant, envelope.context
    world = plant.world_frame()
    rng = np.random.default_rng(11)
    arm = plant.GetModelInstanceByName("ur3")
    for q in POSTURES:
        velocities = rng.uniform(-1.0, 1.0, (2, 6))
        R_WB, p_WB = envelope.pose(np.array(q), 0.05)
        shapes = envelope.shapes("square_flange", True)
        pairs = nearest_points(shapes, R_WB, p_WB, rng.uniform(-0.6, 0.6, (5, 3)))
        links = envelope.link_velocities(R_WB, p_WB, velocities)
        omega, origin = links[:, pairs.link, 0], links[:, pairs.link, 1]
        for k, row in enumerate(shapes.body):
            frame = envelope.bodies[row].body_frame()
            p_BP = frame.CalcPoseInWorld(context).inverse() @ pairs.witness[k].T
            J = plant.CalcJacobianTranslationalVelocity(
                context, JacobianWrtVariable.kV, frame, p_BP, world, world
            )
            for velocity, w, o in zip(velocities, omega[:, k], origin[:, k], strict=True):
                plant.SetVelocities(context, arm, velocity)
                drake = (J @ plant.GetVelocities(context)).reshape(-1, 3)
                assert np.allclose(o + np.cross(w, pairs.witness[k]), drake, atol=1e-12)


def _tcp_motion(envelope, q, qdot):
    """The tcp's position and velocity at `q` moving at `qdot`."""
    plant, context = envelope.plant, envelope.context
    plant.SetPositions(context, plant.GetModelInstanceByName("ur3"), q)
    plant.SetVelocities(context, plant.GetModelInstanceByName("ur3"), qdot)
    tcp = plant.GetFrameByName("tcp")
    p = tcp.CalcPoseInWorld(context).translation()
    v = tcp.CalcSpatialVelocityInWorld(context).translational()
    return p, v


def test_a_body_far_away_allows_full_speed_and_one_on_the_path_stops_the_robot(cell):
    _, envelope = cell
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    intent = MotionIntent(qdot=qdot, moving=True)
    config = SafetyConfig(contact_speed=0.0)  # separation alone
    away = _one_sphere(p + np.array([2.0, 2.0, 1.0]))
    far = assess(envelope, q, qdot, away, intent, config, 3.0, 0.05)
    assert far.limit == 1.0 and far.separation > 1.5 and far.margin > 1.0 and far.moving
    # The hand 8 cm ahead of the tcp along its motion: within S_p at any speed.
    ahead = p + 0.08 * v / np.linalg.norm(v)
    near = assess(envelope, q, qdot, _one_sphere(ahead, radius=0.05), intent, config, 3.0, 0.05)
    assert near.limit == 0.0 and near.separation < 0.05 and near.margin < 0.0 and near.short
    # With the contact speed the arm may go on toward a hand inside S_p, at 80 % of it at most
    # and only as fast as stops short of it; not into one 8 cm ahead.
    hybrid = SafetyConfig()
    near = _one_sphere(p + 0.2 * v / np.linalg.norm(v), radius=0.05)
    slow = assess(envelope, q, qdot, near, intent, hybrid, 3.0)
    assert slow.limit * np.linalg.norm(v) <= 0.8 * 0.25 + 1e-9 and slow.limit > 0.0
    assert slow.margin < 0.0  # inside S_p
    assert (
        assess(envelope, q, qdot, _one_sphere(ahead, radius=0.05), intent, hybrid, 3.0).limit == 0
    )
    # The arm at rest with no plan: not moving, and the hand still within S_p's constant terms.
    still = MotionIntent()
    rest = assess(envelope, q, np.zeros(6), _one_sphere(ahead, radius=0.05), still, config, 3.0)
    assert not rest.moving and rest.limit == 0.0
    off = SafetyConfig(enabled=False)
    assert assess(envelope, q, qdot, _one_sphere(ahead), intent, off, 3.0, 0.05).limit == 1.0


def test_the_creep_toward_a_hand_allows_for_the_plans_speed_ahead_and_the_monitors_lag(cell):
    """Inside S_p the plan creeps toward a hand only as fast as stops short of it. It is
    judged by the plan's velocities until its limit governs the arm (`MotionIntent.ahead`): a
    plan that starts slowly and speeds up meanwhile gets the limit of its faster part, where
    its first velocity alone would let it run at full speed. And the arm may go on for the
    monitor's lag before the limit slows it: a lag lowers the limit."""
    _, envelope = cell
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    hand = _one_sphere(p + 0.14 * v / np.linalg.norm(v), radius=0.05)
    config = SafetyConfig()  # the contact speed: the creep inside S_p

    def limit(intent, lag=0.0):
        return assess(envelope, q, intent.qdot, hand, intent, config, 3.0, None, 0.02, lag).limit

    fast = limit(MotionIntent(qdot=qdot, moving=True))
    assert 0.0 < fast < 1.0
    start = MotionIntent(qdot=0.3 * qdot, moving=True)
    assert limit(start) == 1.0
    speeding = np.stack([0.3 * qdot, 0.6 * qdot, qdot, qdot])
    ahead = dataclasses.replace(start, ahead=speeding)
    assert limit(ahead) == pytest.approx(fast, abs=1e-12)
    assert 0.0 < limit(MotionIntent(qdot=qdot, moving=True), lag=0.04) < fast - 0.03


def test_the_allowed_scale_keeps_the_protective_separation(cell):
    """A hand moving toward the robot's path: at the allowed scale s the plan (scaled by s)
    keeps S_p + slow_band to the body for every pair; 10 % faster it does not; and a robot that
    moves at s keeps a margin of at least slow_band."""
    _, envelope = cell
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    direction = v / np.linalg.norm(v)
    config = SafetyConfig(contact_speed=0.0)  # separation alone
    hand = _one_sphere(p + 0.45 * direction, velocity=-0.3 * direction, radius=0.05)
    s = assess(envelope, q, qdot, hand, MotionIntent(qdot=qdot), config, 3.0, 0.05).limit
    assert 0.05 < s < 0.95
    at_s = assess(envelope, q, s * qdot, hand, MotionIntent(qdot=s * qdot), config, 3.0, 0.05)
    assert at_s.limit == pytest.approx(1.0, abs=1e-9)
    assert at_s.margin >= config.slow_band - 1e-9
    faster = MotionIntent(qdot=1.1 * s * qdot)
    assert assess(envelope, q, 1.1 * s * qdot, hand, faster, config, 3.0, 0.05).limit < 0.95


def test_within_the_slow_band_the_plan_creeps_on_while_it_keeps_s_p(cell):
    """A person standing still beside the path (separation alone, constant human speed): an
    arm within `slow_band` of S_p stands; allowed the band's creep (`band_creep`), it goes on
    toward them at most at BAND_CREEP, at a speed that keeps S_p even at twice its speed, so
    a still person does not hold it forever; closer than the S_p of an arm at rest it stands
    even so."""
    _, envelope = cell
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    direction = v / np.linalg.norm(v)
    config = SafetyConfig(contact_speed=0.0, human_speed=HumanSpeed.CONSTANT)

    def reading(distance, velocity=qdot, creep=True):
        torso = _one_sphere(p + distance * direction, radius=0.15)
        moving = MotionIntent(qdot=velocity, moving=True)
        return assess(envelope, q, velocity, torso, moving, config, 3.0, None, 0.02, 0.0, creep)

    # S_p of the arm at rest: the person's travel at 2.0 m/s over T_r and a period, and Z_d.
    at_rest = NEAR_SPEED * (config.reaction_time + 0.02) + config.human_uncertainty
    distances = np.linspace(0.3, 0.8, 501)
    gaps = np.array([reading(d, 0 * qdot).separation for d in distances])
    in_band = distances[np.argmin(np.abs(gaps - (at_rest + config.slow_band / 2)))]
    too_close = distances[np.argmin(np.abs(gaps - (at_rest - 0.01)))]
    assert reading(in_band, creep=False).limit == 0.0
    creep = reading(in_band).limit
    assert 0.0 < creep <= BAND_CREEP
    # It keeps S_p with room for the servo to overshoot it twofold.
    overshoot = reading(in_band, 2 * creep * qdot)
    assert not overshoot.short and overshoot.margin > 0.0
    assert reading(too_close).limit == 0.0


def test_the_band_creep_comes_after_a_second_held_beside_a_still_body_and_ends_when_it_moves():
    """`band_creep_step`: the creep is allowed once the plan has been held (limit 0) for
    STAND_BEFORE_CREEP beside a body slower than STILL_SPEED; it stays while the arm creeps in
    the band, and ends when the body moves, the plan stops moving, or the arm leaves the band."""
    still = _one_sphere((0.5, 0.0, 0.2))
    moving_body = _one_sphere((0.5, 0.0, 0.2), velocity=(2 * STILL_SPEED, 0.0, 0.0))
    plan = MotionIntent(qdot=np.full(6, 0.3), moving=True, rate=0.0)
    held, creeping, free = (SeparationReading(limit=x) for x in (0.0, BAND_CREEP, 0.5))
    creep, period = BandCreep(), 0.02
    steps = 0
    while not creep.on:
        creep = band_creep_step(creep, held, plan, still, period)
        steps += 1
    assert steps == round(STAND_BEFORE_CREEP / period)
    assert band_creep_step(creep, creeping, plan, still, period).on
    assert not band_creep_step(creep, creeping, plan, moving_body, period).on
    assert not band_creep_step(creep, free, plan, still, period).on
    assert not band_creep_step(creep, held, MotionIntent(), still, period).on
    # Held beside a body that moves, the plan never creeps.
    creep = BandCreep()
    for _ in range(3 * steps):
        creep = band_creep_step(creep, held, plan, moving_body, period)
    assert not creep.on and creep.stood == 0.0


def test_allowed_scale_vectorised_matches_each_entrys_root():
    rng = np.random.default_rng(5)
    a0, a1, a2 = rng.uniform(0, 0.2, 50), rng.uniform(0, 0.3, 50), rng.uniform(0, 0.2, 50)
    gap = a0 + rng.uniform(0.0, 0.6, 50)
    s = allowed_scale(gap, a0, a1, a2)
    assert 0.0 < s < 1.0
    assert np.all(a0 + a1 * s + a2 * s * s <= gap + 1e-12)
    assert np.min(gap - (a0 + a1 * s + a2 * s * s)) == pytest.approx(0.0, abs=1e-12)
    gap[7] = a0[7] - 1e-3
    assert allowed_scale(gap, a0, a1, a2) == 0.0
    assert allowed_scale(np.array([]), np.array([]), np.array([]), np.array([])) == 1.0
    # No room left over the constant terms: standing still is all that keeps S_p.
    assert allowed_scale([0.1], [0.1], [0.0], [0.2]) == 0.0


@pytest.mark.parametrize("human_speed", list(HumanSpeed))
@pytest.mark.parametrize("t_s1", [0.4, 0.03, 0.0])
def test_planned_scales_are_each_pairs_largest_scale_that_keeps_s_p(human_speed, t_s1):
    """Per pair: 1 where full speed keeps S_p within the room, 0 where standing still does
    not, and between them the root, to 1e-7 (the closed form against `planned_distance`,
    over hands coming and going, near and far, with and without a stopping time)."""
    rng = np.random.default_rng(11)
    config = dataclasses.replace(SafetyConfig(), human_speed=human_speed)
    shape = (6, 60)
    v_h = rng.uniform(-3.0, 2.5, shape)
    gap = rng.uniform(0.0, 1.5, shape)
    v_r1 = rng.uniform(0.0, 1.5, shape)
    t_rp = 0.12
    room = gap - config.slow_band
    scales = planned_scales(v_h, gap, v_r1, t_rp, t_s1, config, room)

    def s_p(s):
        return planned_distance(s, v_h, gap, v_r1, t_rp, t_s1, config)

    full, blocked = s_p(1.0) <= room, s_p(0.0) > room
    assert full.any() and blocked.any() and (~full & ~blocked).any()
    assert np.all(scales[full] == 1.0) and np.all(scales[blocked] == 0.0)
    between = ~full & ~blocked
    assert np.all(s_p(scales)[between] <= room[between])
    assert np.all(s_p(scales + 1e-7)[between] > room[between])


def test_the_monitor_system_reads_only_measured_ports_and_logs_each_period(cell):
    """The LeafSystem in a diagram of its own: its reading is `assess`'s, with the gripper's
    opening when `rg2.state_measured` is connected; its log counts the steps, the least
    separation and the time slowed while the plan moves."""
    station, envelope = cell
    design = station.design
    monitor = ControllerSeparationMonitor(design, SafetyConfig(), 3.0, 0.02, envelope=envelope)
    names = {monitor.get_input_port(i).get_name() for i in range(monitor.num_input_ports())}
    assert names == {"ur3.state_estimated", "operator.body", "intent", "rg2.state_measured"}
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    hand = _one_sphere(p + 0.35 * v / np.linalg.norm(v), radius=0.05)
    intent = MotionIntent(qdot=qdot, carrying="oval_flange_1", moving=True, rate=0.5)
    context = monitor.CreateDefaultContext()
    monitor.GetInputPort("ur3.state_estimated").FixValue(context, np.concatenate([q, qdot / 2]))
    monitor.GetInputPort("operator.body").FixValue(context, hand)
    monitor.GetInputPort("intent").FixValue(context, intent)
    unmeasured = monitor.GetOutputPort("reading").Eval(context)
    expected = assess(envelope, q, qdot / 2, hand, intent, SafetyConfig(), 3.0)
    assert unmeasured == expected
    monitor.GetInputPort("rg2.state_measured").FixValue(context, [0.045, 0.0])
    reading = monitor.GetOutputPort("reading").Eval(context)
    assert reading == assess(envelope, q, qdot / 2, hand, intent, SafetyConfig(), 3.0, 0.045)
    assert monitor.GetOutputPort("speed_limit").Eval(context)[0] == reading.limit
    simulator = Simulator(monitor, context)
    simulator.AdvanceTo(0.2)
    log = monitor.log(context)
    assert log.steps in (10, 11)
    assert log.min_separation == pytest.approx(reading.separation)
    assert log.slowed_time == pytest.approx(0.02 * log.steps)
    assert log.stopped_time == 0.0 and log.body_contacts == 0


def test_a_late_body_reading_counts_its_age_and_a_stale_one_stops_the_plan(cell):
    """With a body sensor model (`sensors:`), the monitor adds the reading's age to the reaction
    time it keeps S_p with, and a reading older than `BodyAge.stale_after` is no body seen:
    speed limit 0."""
    station, envelope = cell
    age = BodyAge(stale_after=0.133)
    monitor = ControllerSeparationMonitor(
        station.design, SafetyConfig(), 3.0, 0.02, envelope=envelope, age=age
    )
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    hand = dataclasses.replace(_one_sphere(p + 0.8 * v / np.linalg.norm(v), radius=0.05), stamp=0.0)
    intent = MotionIntent(qdot=qdot, moving=True, rate=1.0)
    context = monitor.CreateDefaultContext()
    monitor.GetInputPort("ur3.state_estimated").FixValue(context, np.concatenate([q, qdot]))
    monitor.GetInputPort("operator.body").FixValue(context, hand)
    monitor.GetInputPort("intent").FixValue(context, intent)
    context.SetTime(0.1)
    late = monitor.GetOutputPort("reading").Eval(context)
    assert not late.stale
    assert late == assess(envelope, q, qdot, hand, intent, SafetyConfig(), 3.0, None, 0.12)
    fresh = assess(envelope, q, qdot, hand, intent, SafetyConfig(), 3.0, None, 0.02)
    assert 0.0 < late.limit < fresh.limit  # the age costs speed
    context.SetTime(0.134)
    stale = monitor.GetOutputPort("reading").Eval(context)
    assert stale.stale and stale.limit == 0.0
    assert monitor.GetOutputPort("speed_limit").Eval(context)[0] == 0.0


def test_the_log_counts_time_stopped_or_slowed_only_where_the_plan_would_move():
    """A stop of the monitor (rate 0 mid-motion) counts as stopped; holding still for bolts
    (rate 0, no plan velocity) does not; a slowed plan counts as slowed; margins and violations
    count only while the arm measurably moves."""
    still = SeparationReading(separation=0.3, margin=-0.1, short=True, limit=0.0, moving=False)
    moving = SeparationReading(separation=0.2, margin=-0.05, short=True, limit=0.4, moving=True)
    qdot = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    steps = [
        (still, MotionIntent(qdot=qdot, moving=False, rate=0.0)),  # stopped by the monitor
        (still, MotionIntent(qdot=np.zeros(6), moving=False, rate=0.0)),  # bolting
        (moving, MotionIntent(qdot=qdot, moving=True, rate=0.4)),  # slowed
        (moving, MotionIntent(qdot=qdot, moving=True, rate=1.0)),  # full speed
    ]
    log = SafetyLog()
    for reading, intent in steps:
        log = log_step(log, reading, intent, 0.02)
    assert log.steps == 4 and log.min_separation == 0.2
    assert log.stopped_time == pytest.approx(0.02) and log.slowed_time == pytest.approx(0.02)
    assert log.violations == 2 and log.min_margin == -0.05 and log.body_contacts == 0


def test_an_arm_moved_from_outside_is_counted_apart_from_the_robots_violations(cell):
    """A joint faster than commanded by more than IMPOSED_SPEED (a push), or moving while the
    robot commands a standstill, is moved from outside: a step closer than S_p then counts as
    `imposed`, not as a violation of the robot's own motion."""
    _, envelope = cell
    q, qdot = np.array(POSTURES[0]), np.array([0.6, 0.3, 0.0, 0.0, 0.0, 0.0])
    p, v = _tcp_motion(envelope, q, qdot)
    hand = _one_sphere(p + 0.08 * v / np.linalg.norm(v), radius=0.05)
    config = SafetyConfig(contact_speed=0.0)  # separation alone
    intent = MotionIntent(qdot=qdot, moving=True)
    own = assess(envelope, q, qdot, hand, intent, config, 3.0, 0.05)
    push = np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    pushed = assess(envelope, q, qdot + push, hand, intent, config, 3.0, 0.05)
    assert own.margin < 0 and not own.imposed
    assert pushed.margin < 0 and pushed.imposed
    held = assess(envelope, q, qdot, hand, MotionIntent(), config, 3.0, 0.05)
    assert held.imposed
    log = SafetyLog()
    for reading, why in ((own, intent), (pushed, intent), (held, MotionIntent())):
        log = log_step(log, reading, why, 0.02)
    assert log.violations == 1 and log.imposed == 2
    assert log.to_json()["imposed"] == 2
