"""The safety-rated sensor (`safety.sensor`): its rays see what is there, what no unit sees
counts as occupied unless nobody could have come there, and the station's safety function reads
only it and the arm's encoders: a silent unit stops the arm, a falsified tracker changes
nothing."""

import sys
from pathlib import Path

import numpy as np
import pytest

from hrc_drake.cell import volumetric
from hrc_drake.cell.ports import SafetyMode
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.ssm import NEAR_SPEED, function_settings, planning_settings
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.safety_function import StopCause
from hrc_drake.hri.activity import min_jerk
from hrc_drake.scenario.safety import HumanSpeed, SafetyConfig, SafetySensorConfig
from hrc_drake.scenario.schema import ScenarioError

sys.path.insert(0, str(Path(__file__).parent))
from test_safety_function import Cell, _tcp

SENSOR = "{safety: {sensor: {enabled: true}}}"
GRID = volumetric.VoxelGrid.spanning([-0.3, -0.55, 0.0], [1.15, 0.55, 0.8], 0.05)
TABLE = (-0.25, 0.75, -0.5, 0.5)


def _overhead():
    return volumetric.unit_rays("overhead", [0.4, 0, 2.4], [0.4, 0, 0], (68, 42), 4.0, 0.07, GRID)


def _scene(centres, radii):
    return volumetric.Occluders(np.atleast_2d(centres), np.atleast_1d(radii), TABLE)


def test_a_ray_stops_at_the_first_thing_it_meets_and_else_at_the_table():
    rays = _overhead()
    down = int(np.argmax(rays.directions[:, 2] * -1.0))  # the ray nearest straight down
    ball = rays.origin + 1.5 * rays.directions[down]
    depth, hit = volumetric.cast(rays, _scene(ball, 0.1))
    assert depth[down] == pytest.approx(1.4, abs=1e-9) and hit[down]
    empty, met = volumetric.cast(rays, _scene(np.zeros((0, 3)), np.zeros(0)))
    # Over the table a ray ends on its top (the taught background: no hit); beyond, its reach.
    assert empty[down] == pytest.approx(2.4 / -rays.directions[down, 2]) and not met.any()


def test_anything_as_wide_as_the_detection_capability_is_met_by_a_ray():
    """A sphere of the unit's detection capability anywhere in the monitored space, in the
    open, is met by at least one of the unit's rays."""
    rays, rng = _overhead(), np.random.default_rng(3)
    upper = GRID.lower + np.array(GRID.shape) * GRID.pitch
    for centre in rng.uniform([*GRID.lower[:2], 0.05], upper, size=(200, 3)):
        _, hit = volumetric.cast(rays, _scene(centre, 0.07 / 2))
        assert hit.any(), centre


def test_volume_no_unit_sees_is_occupied_unless_nobody_could_have_come_there():
    """A ball hides the volume under it from the one unit: hidden volume a person could have
    reached (all of it, at power-on) is occupied; hidden volume that was seen empty a frame ago
    and lies beyond 2 m/s of anything possibly occupied is not (the arm's shadow)."""
    rays = _overhead()
    ball = np.array([0.4, 0.0, 0.5])
    depth, hit = volumetric.cast(rays, _scene(ball, 0.1))
    seen, points = volumetric.view(rays, depth, hit, GRID, 0.01)
    nobody = (np.zeros((0, 3)), np.zeros(0))
    fixed = np.zeros(GRID.size, dtype=bool)
    under = GRID.index(np.array([[0.4, 0.0, 0.2]]))[0]
    everywhere = np.ones(GRID.size, dtype=bool)
    flat, met_points, _ = volumetric.unexplained(
        GRID, seen, points, nobody, 0.05, fixed, everywhere
    )
    assert under in flat and len(met_points) > 0
    assert np.all(np.linalg.norm(met_points - ball, axis=1) == pytest.approx(0.1, abs=1e-6))
    # Seen free a frame ago, nothing possibly occupied within reach: not a person.
    reach = volumetric.dilate(GRID, np.zeros(GRID.size, dtype=bool), NEAR_SPEED / 30.0)
    flat, _, _ = volumetric.unexplained(GRID, seen, points, nobody, 0.05, fixed, reach)
    assert under not in flat
    # The same shadow, with something possibly there a voxel away: it may have come in.
    beside = np.zeros(GRID.size, dtype=bool)
    beside[GRID.index(np.array([[0.45, 0.0, 0.2]]))[0]] = True
    reach = volumetric.dilate(GRID, beside, NEAR_SPEED / 30.0)
    flat, _, _ = volumetric.unexplained(GRID, seen, points, nobody, 0.05, fixed, reach)
    assert under in flat


def test_the_robot_explains_what_it_hides_within_its_margin():
    rays = _overhead()
    ball = np.array([0.4, 0.0, 0.5])
    depth, hit = volumetric.cast(rays, _scene(ball, 0.1))
    seen, points = volumetric.view(rays, depth, hit, GRID, 0.01)
    everywhere = np.ones(GRID.size, dtype=bool)
    robot = (ball[None, :], np.array([0.1]))
    flat, met_points, _ = volumetric.unexplained(
        GRID, seen, points, robot, 0.05, np.zeros(GRID.size, dtype=bool), everywhere
    )
    assert len(met_points) == 0  # every point met is on the robot
    centres = GRID.centres(flat)
    assert np.all(np.linalg.norm(centres - ball, axis=1) > 0.15 - 1e-9)


def test_a_person_is_grown_at_most_by_what_they_could_reach():
    start = np.zeros(GRID.size, dtype=bool)
    voxel = GRID.index(np.array([[0.4, 0.0, 0.4]]))[0]
    start[voxel] = True
    grown = GRID.centres(np.flatnonzero(volumetric.dilate(GRID, start, 0.1)))
    offsets = np.abs(grown - GRID.centres([voxel])).max(axis=1)
    assert offsets.max() == pytest.approx(0.1) and len(grown) == 5**3


def test_with_the_sensor_the_function_and_the_planner_take_the_unmeasured_speed():
    safety = SafetyConfig(sensor=SafetySensorConfig(enabled=True))
    function = function_settings(safety)
    assert function.human_speed == HumanSpeed.CONSTANT
    assert function.reaction_time == pytest.approx(safety.reaction_time + 0.055)
    assert planning_settings(safety).reaction_time == function.reaction_time
    assert function_settings(SafetyConfig()) == SafetyConfig()


def test_bad_safety_sensor_values_are_refused():
    for text, key in (
        ("{safety: {sensor: {enabled: true, units: []}}}", r"safety\.sensor\.units"),
        ("{safety: {sensor: {enabled: true, voxel: 0}}}", r"safety\.sensor\.voxel"),
        (
            "{safety: {sensor: {enabled: true, space: [[0, 0, 1], [1, 1, 0]]}}}",
            r"safety\.sensor\.space",
        ),
        (
            "{safety: {sensor: {enabled: true, units: [{response_time: 0.01}]}}}",
            r"response_time.*one frame period",
        ),
        ("{faults: [!SafetySensorSilent {task: 1}]}", r"needs `safety\.sensor\.enabled"),
        (
            "{safety: {sensor: {enabled: true}}, faults: [!SafetySensorSilent {unit: top}]}",
            r"no unit 'top'",
        ),
    ):
        with pytest.raises(ScenarioError, match=key):
            load_cell_scenario("row1-optimal", [LEAN, text])


# --- the station's safety function, reading the sensor -------------------------------------


def _reaching_hand(scenario, offset):
    """The hand of `test_safety_function`'s reach toward the moving arm."""
    q0 = np.array(scenario.station.ur3.ready, float)
    rest = np.array(scenario.body.rest_hand, float)
    target = _tcp(make_cell_station(scenario), q0 + offset) + np.array([0.15, 0.0, 0.0])

    def hand(now, activity, part):
        t = now - 0.3
        out = min_jerk(t / 0.4) - min_jerk((t - 1.9) / 0.4)
        return rest + out * (target - rest)

    return hand


OFFSET = np.array([0, 0.5, -0.8, 0, 0, 0])


def _reach(texts):
    hand = _reaching_hand(load_cell_scenario("row1-optimal", [LEAN]), OFFSET)
    cell = Cell([SENSOR, *texts], OFFSET, speed=1.5, body_script=hand)
    cell.advance_to(3.0)
    return cell


def test_the_sensor_stops_the_arm_for_a_reaching_hand_within_the_standard():
    """The arm reaches toward the operator at 1.5 rad/s while the hand reaches toward it: the
    function, reading only the cameras, stops it, and by the run's own check (the true body)
    no step inside S_p moves faster than ISO/TS 15066 permits and nothing touches."""
    cell = _reach([])
    log = cell.log()
    assert log.safeguard_stops >= 1
    check = cell.check()
    assert check.body_contacts == 0 and check.passed


def test_the_function_reads_no_body_signal_but_the_sensor():
    """The tracker's port blanked for the whole reach (a tracker loss) and noisy: the safety
    function, which reads only the safety sensor and the encoders, decides as before, mode for
    mode and stop for stop."""
    plain = _reach([])
    falsified = _reach(
        [
            "{faults: [!TrackerLoss {task: 1, after: 0.0, duration: 10.0}], "
            "sensors: {preset: realistic, body: {noise: 0.3, dropout: 0.5}}}"
        ]
    )
    assert falsified.modes == plain.modes
    assert falsified.log().events == plain.log().events
    assert plain.log().safeguard_stops >= 1  # there was something to decide


def test_a_unit_that_stops_sending_is_a_safeguard_stop_within_its_response_time():
    """The left unit falls silent at 1.0 s (its last frame taken then): the function stops the
    arm within the unit's response time and one period of the function, holds it while the
    unit is silent, and lets it go once frames come again."""
    cell = Cell([SENSOR, "{body: {enabled: false}}"], [0.6, 0, 0, 0, 0, 0], speed=0.2)
    cell.advance_to(1.0 - 1e-9)
    assert cell.modes[-1] != SafetyMode.SAFEGUARD_STOP
    context = cell.side.GetMyContextFromRoot(cell.simulator.get_mutable_context())
    port = cell.side.GetInputPort("sim.safety_sensor.silent")
    port.FixValue(context, [0.0, 1.0, 0.0])
    cell.advance_to(2.0)
    response, period = 0.055, cell.scenario.run.period
    stop = next(s.time for s, m in zip(cell.samples, cell.modes, strict=True) if m.stopped)
    assert stop <= 1.0 + response + period + 1e-6
    assert cell.log().events[0].endswith(f"safeguard stop: {StopCause.STALE_SENSOR.value}")
    assert cell.modes[-1] == SafetyMode.SAFEGUARD_STOP
    port.FixValue(context, [0.0, 0.0, 0.0])
    cell.advance_to(3.0)
    assert cell.modes[-1] != SafetyMode.SAFEGUARD_STOP


def test_a_sensor_s_many_spheres_are_cut_to_those_that_can_matter(monkeypatch):
    """The function first keeps, of a reading of hundreds of spheres, those that may bear on
    its verdict (`_nearby`): every verdict is the one the whole reading gives."""
    from hrc_drake.cell.robot_envelope import RobotEnvelope
    from hrc_drake.cell.scenario import cell_design, motion_options
    from hrc_drake.cell.station import safety_function
    from hrc_drake.tasks.spec import load_spec

    scenario = load_cell_scenario("row1-optimal", [LEAN, SENSOR])
    envelope = RobotEnvelope(cell_design(scenario, load_spec(scenario.assembly_path)))
    config = function_settings(scenario.safety)
    acceleration = motion_options(scenario).joint_acceleration_limit
    rng = np.random.default_rng(5)
    q0 = np.array(scenario.station.ur3.ready, float)
    decided = []
    for _ in range(40):
        spot = rng.uniform([-0.3, -0.55, 0.05], [1.15, 0.55, 0.8])
        centres = spot + rng.normal(0.0, 0.08, size=(300, 3))
        body = volumetric.as_body(GRID, np.zeros(0, dtype=int), centres, 0.01, 0.64, 0.0)
        q, v = q0 + rng.normal(0, 0.3, 6), rng.normal(0, 0.8, 6)

        def verdict(q=q, v=v, body=body):
            return safety_function.judge_separation(
                envelope, q, v, 0.06, None, body, config, acceleration, 0.02
            )

        cut = verdict()
        monkeypatch.setattr(safety_function, "PRUNE_ABOVE", 10**6)
        whole = verdict()
        monkeypatch.setattr(safety_function, "PRUNE_ABOVE", 64)
        assert (cut.margin < 0, cut.clear, cut.reduced, cut.contact) == (
            whole.margin < 0,
            whole.clear,
            whole.reduced,
            whole.contact,
        )
        if whole.margin < 0:
            assert cut.margin == pytest.approx(whole.margin)
        decided.append(whole.margin < 0 or whole.reduced)
    assert any(decided) and not all(decided)  # the draws test both answers


def test_a_monitored_space_no_unit_sees_is_refused_with_the_fix():
    from hrc_drake.cell_models import CellModelError

    away = "{safety: {sensor: {enabled: true, units: [{target: [3, 0, 2]}]}}}"
    with pytest.raises(CellModelError, match=r"outside every unit's view.*aim the units"):
        make_cell_station(load_cell_scenario("row1-optimal", [LEAN, away]))
