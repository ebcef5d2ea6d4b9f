"""The operator's body in the cell and speed and separation monitoring (ISO/TS 15066 §5.5.4)."""

import numpy as np
import pytest

from hrc_drake.cell.builder import CellScenario, build_cell
from hrc_drake.cell.operator_body import ReachInto, body_pose
from hrc_drake.cell.run import run_scenario
from hrc_drake.cell.safety import allowed_scale
from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario
from hrc_drake.hri.scenario import BodyConfig, ScenarioError
from hrc_drake.motion.poses import part_pose
from hrc_drake.tasks.spec import load_spec


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
    scenario = load_cell_scenario("row1-optimal", LEAN)
    frames = build_cell(
        CellScenario(design=cell_design(scenario, load_spec()), include_robot=False)
    ).frames
    above_seat = part_pose(frames, "F1", []).translation() + np.array([0.0, 0.0, 0.12])
    hand = ReachInto(BodyConfig().rest_hand, above_seat, step=1, dwell=2.0)
    result = run_scenario(scenario, body_script=hand)
    assert hand.start is not None
    assert result.error is None and result.done
    assert result.names == list(scenario.minimum_effort) and result.collisions == []
    safety = result.safety
    assert safety.violations == 0 and safety.body_contacts == 0
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
    assert set(data) >= {"min_separation", "min_margin", "violations", "slowed_time"}


@pytest.mark.slow
def test_a_row_with_a_mistake_and_undo_runs_with_the_body_and_no_violation():
    result = run_scenario("row7-forces-9", scenario_text=LEAN)
    assert result.error is None and result.done and result.collisions == []
    assert result.safety.violations == 0 and result.safety.body_contacts == 0
    assert result.safety.min_separation > 0
    short = "{body: {enabled: false}, run: {max_sim_time: 1.0}}"
    off = run_scenario("row7-forces-9", scenario_text=[LEAN, short])
    assert off.safety is None and off.to_json()["safety"] is None
