"""Friction grasps: the part is carried by the fingers' contact and friction alone, so too weak a
grip lets it slip, and the cell detects that from the gripper's own measurements."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from hrc_drake.cell.scenario import contact_material, load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.gripper import RG2_MIN_FORCE
from hrc_drake.motion.poses import part_pose, tcp_pose
from hrc_drake.rg2_kinematics import pad_travel_rate
from hrc_drake.robot_models import set_rg2_opening
from hrc_drake.scenario.schema import Scenario


@pytest.fixture(scope="module")
def station():
    return make_cell_station(Scenario())


def _pads_in_tcp(station, opening: float) -> RigidTransform:
    """Where the model's pads' centre (midway between the finger frames, on the pads' faces)
    stands in the tcp frame with the fingers `opening` apart."""
    plant = station.plant
    context = plant.CreateDefaultContext()
    set_rg2_opening(plant, context, opening)
    tcp = plant.GetFrameByName("tcp")
    centre = np.mean(
        [
            plant.GetFrameByName(name).CalcPose(context, tcp).translation()
            for name in ("left_finger", "right_finger")
        ],
        axis=0,
    )
    return RigidTransform(centre)


@pytest.mark.parametrize(
    ("part", "token", "depth"), [("square_flange", "S23", 0.0163), ("oval_flange_1", "F1", 0.0)]
)
def test_the_grasp_puts_the_pads_on_the_parts_grasp_frame(station, part, token, depth):
    """The tcp the planner takes to hold a part (`tcp_pose`, in the tray and seated) puts the
    model's pads, closed on the part's width, on the part's `grasp` frame; for the square flange
    (90 mm) the tcp stands 16.3 mm further along the approach than there, where the RG2's pads
    swing back as they open, for the oval flanges (45 mm, the tcp's own opening) nowhere else."""
    frames, plant = station.frames, station.plant
    model = station.instances[part]
    X_part_grasp = plant.GetFrameByName("grasp", model).GetFixedPoseInBodyFrame()
    X_tcp_pads = _pads_in_tcp(station, frames.widths[part])
    for X_W_part in (frames.homes[part], part_pose(frames, token, {token})):
        X_W_tcp = tcp_pose(frames, part, X_W_part)
        X_W_grasp = X_W_part @ X_part_grasp
        np.testing.assert_allclose(
            (X_W_tcp @ X_tcp_pads).translation(), X_W_grasp.translation(), atol=1e-6
        )
        assert X_W_grasp.InvertAndCompose(X_W_tcp).translation() == pytest.approx(
            [0.0, 0.0, depth], abs=2e-4
        )


def _force_to_hold(station, part: str, friction: float) -> float:
    """The grip force [N] two pads need to hold `part` still against gravity, its friction on
    the cell `friction`: its weight over twice the pads' friction coefficient on it (Drake
    combines two materials' coefficients as 2 μ1 μ2 / (μ1 + μ2); SAP uses the dynamic one), less
    what the weight itself adds to the squeeze through the RG2's linkage (`pad_travel_rate`)."""
    plant = station.plant
    inspector = station.scene_graph.model_inspector()
    mass = station.part_body(part).default_mass()
    pad = next(
        g
        for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName("left_finger"))
        if inspector.GetName(g).endswith("pad")
    )
    pad_mu = inspector.GetProximityProperties(pad).GetProperty("material", "coulomb_friction")
    pad_mu = pad_mu.dynamic_friction()
    # Drake's CoulombFriction::CombineWithOtherFrictionCoefficients.
    mu = 2.0 * pad_mu * friction / (pad_mu + friction)
    weight = mass * -plant.gravity_field().gravity_vector()[2]
    return weight / (2.0 * mu) + weight * pad_travel_rate(station.frames.widths[part])


def test_the_linkage_lets_the_rg2s_weakest_grip_carry_the_square_flange(station):
    """Hanging from the pads, the square flange (90 mm) pulls them away from the flange, which
    the RG2's linkage turns into squeeze (0.61 of its weight): its weakest grip holds it on the
    cell's friction (a lean row 1 run carries and seats it at 3 N), not on a slippery one."""
    friction = contact_material(Scenario()).dynamic_friction
    assert _force_to_hold(station, "square_flange", friction) < RG2_MIN_FORCE
    assert _force_to_hold(station, "square_flange", 0.15) > 2 * RG2_MIN_FORCE


def test_on_slippery_parts_the_rg2s_weakest_grip_cannot_hold_the_square_flange_and_the_default_can(
    station,
):
    """The force balance behind two runs elsewhere: on slippery parts (0.15) at the RG2's least
    force the square flange slips and the task is handed over (tests/test_faults.py); at the
    default grip every Table 2 row carries it with no part dropped (tests/test_closed_loop.py),
    on the cell's friction and with margin on slippery parts too. On the cell's friction the
    linkage's squeeze lets even the least force hold it (the test above), so the balance that
    makes a weak grip slip needs slippery parts."""
    default = Scenario().station.rg2.grip_force
    needed = _force_to_hold(station, "square_flange", 0.15)
    assert RG2_MIN_FORCE < needed < default / 2
    friction = contact_material(Scenario()).dynamic_friction
    assert _force_to_hold(station, "square_flange", friction) < default / 2


def test_the_grip_force_is_the_rg2s():
    with pytest.raises(ValueError, match=r"station\.rg2\.grip_force: the RG2 grips with 3 to 40 N"):
        load_cell_scenario(None, "{station: {rg2: {grip_force: 2.0}}}")
