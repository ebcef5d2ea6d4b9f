"""Friction grasps: the part is carried by the fingers' contact and friction alone, so too weak a
grip lets it slip, and the cell detects that from the gripper's own measurements."""

import pytest

from hrc_drake.cell.scenario import load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.gripper import RG2_MIN_FORCE
from hrc_drake.scenario.schema import Scenario


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


def test_the_rg2s_weakest_grip_cannot_hold_the_square_flange_and_the_default_can():
    """The force balance behind two runs elsewhere: at the RG2's least force the square flange
    slips and the task is handed over (tests/test_faults.py); at the default grip every Table 2
    row carries it with no part dropped (tests/test_closed_loop.py)."""
    needed = _force_to_hold("square_flange")
    default = Scenario().station.rg2.grip_force
    assert RG2_MIN_FORCE < needed < default / 2


def test_the_grip_force_is_the_rg2s():
    with pytest.raises(ValueError, match=r"station\.rg2\.grip_force: the RG2 grips with 3 to 40 N"):
        load_cell_scenario(None, "{station: {rg2: {grip_force: 2.0}}}")
