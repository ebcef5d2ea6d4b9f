"""The configuration sensor (hrc_drake.cell.station.slot_monitor) reads every part's world pose,
wherever the part lies: in the tray, seated, on the table, askew on the plate. (Seating and its
tolerances are tested in tests/test_cell.py.)"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from hrc_drake.cell.ports import PartPlacement, PartStatus, placement_transform, pose_tuple
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.station import make_cell_station, simulate_station
from hrc_drake.cell.station.contacts import geometry_owners, owner_pairs

SETTLE = 0.5  # s: long enough for a part laid on a surface to come to rest
PENETRATION = 0.0002  # m: a part laid on a surface touches it


@pytest.fixture(scope="module")
def station():
    return make_cell_station(load_cell_scenario("row1-optimal", LEAN))


def _gap(station, context, part: str, surface: str) -> float:
    """The smallest signed distance between the part's and the surface body's geometries."""
    plant = station.plant
    query = station.diagram.GetOutputPort("sim.query_object").Eval(
        station.diagram.GetMyContextFromRoot(context)
    )
    mine = plant.GetCollisionGeometriesForBody(station.part_body(part))
    theirs = plant.GetCollisionGeometriesForBody(plant.GetBodyByName(surface))
    return min(
        query.ComputeSignedDistancePairClosestPoints(a, b).distance for a in mine for b in theirs
    )


def _lay(station, context, part: str, X_above: RigidTransform, surface: str) -> RigidTransform:
    """Put `part` with the orientation and horizontal position of `X_above`, lowered until it
    just touches the body `surface`; its pose."""
    plant = station.plant
    plant_context = plant.GetMyContextFromRoot(context)
    body = station.part_body(part)
    plant.SetFreeBodyPose(plant_context, body, X_above)
    drop = _gap(station, context, part, surface) + PENETRATION
    X_WP = RigidTransform(X_above.rotation(), X_above.translation() - [0.0, 0.0, drop])
    plant.SetFreeBodyPose(plant_context, body, X_WP)
    return X_WP


def _same_pose(placement: PartPlacement, X: RigidTransform, tolerance: float) -> bool:
    """The placement's pose is X: the translation, and the quaternion up to its sign."""
    pose, expected = np.array(placement.pose), np.array(pose_tuple(X))
    if len(pose) != 7:
        return False
    position = np.abs(pose[:3] - expected[:3]).max()
    turn = min(np.abs(pose[3:] - expected[3:]).max(), np.abs(pose[3:] + expected[3:]).max())
    return max(position, turn) <= tolerance


def _body_pose(station, context, part: str) -> RigidTransform:
    plant = station.plant
    return station.part_body(part).EvalPoseInWorld(plant.GetMyContextFromRoot(context))


def _lay_three(station, context) -> dict[str, RigidTransform]:
    """oval_flange_1 tilted on the plate beside slot 2, off any seat; oval_flange_2 seated at
    F1; square_flange on the table, away from the plate and the tray."""
    X_W_slot2 = station.plant.GetFrameByName("slot_2").CalcPoseInWorld(
        station.plant.GetMyContextFromRoot(context)
    )
    askew = X_W_slot2 @ RigidTransform(RollPitchYaw(0.15, 0.0, 0.3), [0.0, 0.03, 0.05])
    on_table = RigidTransform(RollPitchYaw(0.0, 0.0, 0.7), [0.55, 0.3, 0.05])
    seat = station.placement_poses({"oval_flange_2": "F1"})["oval_flange_2"]
    return {
        "oval_flange_1": _lay(station, context, "oval_flange_1", askew, "base_plate"),
        "oval_flange_2": _lay(station, context, "oval_flange_2", seat, "base_plate"),
        "square_flange": _lay(station, context, "square_flange", on_table, "table"),
    }


def test_a_part_on_the_table_reads_transit_where_it_was_put(station):
    """Read at once: the pose is the one set, to 1e-9; a part on the table is in transit, and
    the sensor reports the pose of the parts still in the tray too."""
    context = station.create_default_context()
    tray = {p: _body_pose(station, context, p) for p in station.design.instance_names}
    laid = _lay_three(station, context)
    reading = station.configuration(context)
    assert reading.status("square_flange") is PartStatus.TRANSIT
    assert reading.tokens() == frozenset()
    for part, X_WP in laid.items():
        assert _same_pose(reading.placement(part), X_WP, 1e-9), part
        assert placement_transform(reading.placement(part)).IsNearlyEqualTo(X_WP, 1e-9), part
    fresh = station.configuration(station.create_default_context())
    for part, X_WP in tray.items():
        assert fresh.status(part) is PartStatus.TRAY, part
        assert _same_pose(fresh.placement(part), X_WP, 1e-9), part


def test_parts_at_rest_off_their_seats_read_where_they_lie(station):
    """After the parts come to rest (the contacts are those of a simulated step): the one on
    the table is in transit, the one askew on the plate misplaced, the seated one seated; each
    reads its body's pose as it lies, near where it was put."""
    context = station.create_default_context()
    laid = _lay_three(station, context)
    simulate_station(station, context, SETTLE)
    results = station.diagram.GetOutputPort("sim.contact_results").Eval(
        station.diagram.GetMyContextFromRoot(context)
    )
    touching = {
        frozenset((a.model, b.model))
        for a, b in owner_pairs(results, geometry_owners(station.plant))
    }
    assert frozenset(("table", "square_flange")) in touching
    assert frozenset(("base_plate", "oval_flange_1")) in touching
    reading = station.configuration(context)
    assert reading.status("square_flange") is PartStatus.TRANSIT
    assert reading.status("oval_flange_1") is PartStatus.MISPLACED
    assert reading.status("oval_flange_2") is PartStatus.SEATED
    assert reading.tokens() == frozenset({"F1"})
    for part, X_laid in laid.items():
        X_WP = _body_pose(station, context, part)
        assert _same_pose(reading.placement(part), X_WP, 1e-12), part
        assert np.linalg.norm(X_WP.translation() - X_laid.translation()) < 0.005, part


def test_a_placement_without_a_pose_has_no_transform():
    with pytest.raises(ValueError, match="a transit placement without a pose"):
        placement_transform(PartPlacement(PartStatus.TRANSIT))
    with pytest.raises(ValueError, match="a placement pose of 3 values; it must be 7"):
        placement_transform(PartPlacement(PartStatus.TRANSIT, pose=(0.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match="has a zero quaternion"):
        placement_transform(PartPlacement(PartStatus.TRANSIT, pose=(0.0,) * 7))
    # Hashable and frozen, pose and all.
    placement = PartPlacement(PartStatus.TRANSIT, pose=pose_tuple(RigidTransform([1.0, 2.0, 3.0])))
    assert placement in {placement}
    assert placement_transform(placement).IsExactlyEqualTo(RigidTransform([1.0, 2.0, 3.0]))
