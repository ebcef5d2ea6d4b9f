"""Friction grasps: the part is carried by the fingers' contact and friction alone, so too weak a
grip lets it slip, and the cell detects that from the gripper's own measurements."""

import pytest

from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.gripper import RG2_MIN_FORCE
from hrc_drake.scenario.schema import Scenario

# The operator takes the square flange (the heaviest part) first.
SQUARE_FIRST = "{operator: {deviations: [{step: 1, task: S23}]}}"


def _force_to_hold(part: str) -> float:
    """The grip force [N] two pads need to hold `part` still against gravity: its weight over
    twice the pads' friction coefficient on it (Drake combines two materials' coefficients as
    2 μ1 μ2 / (μ1 + μ2); SAP uses the dynamic one)."""
    station = make_cell_station(Scenario())
    plant = station.plant
    inspector = station.scene_graph.model_inspector()
    mass = station.part_body(part).default_mass()
    pad = next(
        g
        for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName("left_finger"))
        if inspector.GetName(g).endswith("pad")
    )
    pad = inspector.GetProximityProperties(pad).GetProperty("material", "coulomb_friction")
    pad_mu, part_mu = pad.dynamic_friction(), station.scenario.physics.contact.dynamic_friction
    # Drake's CoulombFriction::CombineWithOtherFrictionCoefficients.
    mu = 2.0 * pad_mu * part_mu / (pad_mu + part_mu)
    gravity = -plant.gravity_field().gravity_vector()[2]
    return mass * gravity / (2.0 * mu)


@pytest.mark.slow
def test_a_grip_too_weak_for_the_part_lets_it_slip_and_the_task_is_handed_over():
    needed = _force_to_hold("square_flange")
    default = Scenario().station.rg2.grip_force
    # The RG2's weakest grip is below what the square flange needs; the default is well above.
    assert RG2_MIN_FORCE < needed < default / 2
    weak = load_cell_scenario(
        "row1-optimal",
        [LEAN, SQUARE_FIRST, f"{{station: {{rg2: {{grip_force: {RG2_MIN_FORCE}}}}}}}"],
    )
    result = run_scenario(weak)
    # The Supervisor saw the fingers close past the part's width (no grip), picked it again
    # from where it fell (run.recover_tries, 2), saw it slip each time, and handed the task
    # over: the operator seats the square by hand, and the light oval flanges hold.
    assert any("square_flange is not in the gripper" in event for event in result.events)
    first = result.tasks[0]
    assert first.observed == "S23"
    assert "square_flange slipped out of the gripper 3 times" in first.handed_over
    assert result.done and not any(t.handed_over for t in result.tasks[1:])
    assert result.collisions == []


@pytest.mark.slow
def test_the_default_grip_carries_the_heaviest_part():
    result = run_scenario("row1-optimal", scenario_text=[LEAN, SQUARE_FIRST])
    assert result.error is None and result.done
    assert result.tasks[0].observed == "S23"
    assert result.collisions == []


def test_the_grip_force_is_the_rg2s():
    with pytest.raises(ValueError, match=r"station\.rg2\.grip_force: the RG2 grips with 3 to 40 N"):
        load_cell_scenario(None, "{station: {rg2: {grip_force: 2.0}}}")
