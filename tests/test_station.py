"""The simulated station: one diagram from one scenario, the ports of a real cell, and what only
a simulator does (the simulated operator and its bolts) kept inside."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from hrc_drake.cell.controller.build import COMMANDED, MEASURED, PENDANT, WATCHDOG
from hrc_drake.cell.controller.supervisor import Mode
from hrc_drake.cell.run.run import build_closed_loop
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.welds import Weld
from hrc_drake.resources import scenarios_dir
from hrc_drake.scenario.load import table2_scenarios

CATALOGUE = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))


@pytest.mark.parametrize("name", CATALOGUE)
def test_every_catalogue_scenario_builds_a_station_with_the_ports_of_a_real_cell(name):
    station = make_cell_station(load_cell_scenario(name, LEAN))
    diagram = station.diagram
    inputs = {diagram.get_input_port(i).get_name() for i in range(diagram.num_input_ports())}
    outputs = {diagram.get_output_port(i).get_name() for i in range(diagram.num_output_ports())}
    # What a controller may use is exactly the contract; the rest is marked simulation-only.
    assert {n for n in inputs if not n.startswith("sim.")} == {*COMMANDED, *PENDANT, *WATCHDOG}
    # Beside them, what its servo followed (RTDE's `target_q`), one of the `LINK_READINGS`.
    assert {n for n in outputs if not n.startswith("sim.")} == {*MEASURED, "ur3.target"}
    assert diagram.GetInputPort("ur3.position").size() == 6
    assert diagram.GetOutputPort("rg2.state_measured").size() == 2


def test_the_station_comes_from_the_scenario():
    text = "{station: {ur3: {kp: [3000, 3000, 1500, 400, 400, 400]}, rg2: {initial_opening: 0.05}}}"
    station = make_cell_station(load_cell_scenario("row1-optimal", [LEAN, text]))
    context = station.create_default_context()
    opening = station.diagram.GetOutputPort("rg2.state_measured").Eval(context)[0]
    assert opening == pytest.approx(0.05)
    plant = station.plant
    pan = plant.GetJointActuatorByName("shoulder_pan_motor")
    assert pan.get_controller_gains().p == pytest.approx(3000.0)


@pytest.mark.slow
def test_parts_are_bolted_where_they_rest_and_unbolted_for_an_undo():
    """Row 7: F1, S23, then F03 lands in F02 (a mistake), undo, F03. The simulated operator's
    bolts take in the seat each part rests in once the robot has let it go, fixing it where it
    sits; before the undo it takes the bolts out."""
    row = next(r for r in table2_scenarios() if r.name == "row7-forces-9")
    loop = build_closed_loop(load_cell_scenario(row.name, LEAN))
    plant = loop.station.plant
    at_bolting: dict[tuple[str, str], RigidTransform] = {}
    apply_welds = loop.cell.apply_welds

    def note_where_bolts_take(root):
        # The loop applies the bolts the station wants at the step they change: a new one takes
        # where its part sits at that moment.
        applied = apply_welds(root)
        for weld in applied:
            if (weld.part, weld.seat) not in at_bolting:
                body = loop.station.part_body(weld.part)
                pose = plant.EvalBodyPoseInWorld(plant.GetMyContextFromRoot(root), body)
                at_bolting[(weld.part, weld.seat)] = pose
        return applied

    loop.cell.apply_welds = note_where_bolts_take
    welds = []
    t = 0.0
    while loop.advance_to(t) not in (Mode.DONE, Mode.FAILED) and t < 60:
        t += 0.5
        bolts = {(w.part, w.seat) for w in loop.station.wanted_welds(loop.root_context)}
        if bolts and (not welds or welds[-1] != bolts):
            welds.append(bolts)
    assert loop.status.mode == Mode.DONE and loop.status.error is None
    ends = [w for w in welds if all(isinstance(x, tuple) for x in w)]
    assert {("oval_flange_1", "F1")} in ends
    # The flange bolted on the wrong row is unbolted before the robot takes it back ...
    wrong = {
        ("oval_flange_1", "F1"),
        ("square_flange", "S23"),
        ("oval_flange_2", "square_flange/row_1"),
    }
    right = {
        ("oval_flange_1", "F1"),
        ("square_flange", "S23"),
        ("oval_flange_2", "square_flange/row_2"),
    }
    assert wrong in ends and right in ends
    assert (
        ends.index(wrong)
        < ends.index({("oval_flange_1", "F1"), ("square_flange", "S23")}, ends.index(wrong))
        < ends.index(right)
    )
    # ... and the bolts the station holds at the end are those of the final configuration.
    final = loop.station.wanted_welds(loop.root_context)
    assert all(isinstance(w, Weld) for w in final)
    assert {(w.part, w.seat) for w in final} == right
    # A bolt moves its part by less than 0.1 mm: from the moment it took (the part let go and
    # at rest in its pocket) through the rest of the run, the robot's retreat and the next
    # tasks beside it.
    plant_context = plant.GetMyContextFromRoot(loop.root_context)
    for weld in final:
        X_bolted = at_bolting[(weld.part, weld.seat)]
        X_now = plant.EvalBodyPoseInWorld(plant_context, loop.station.part_body(weld.part))
        moved = X_bolted.InvertAndCompose(X_now)
        assert np.linalg.norm(moved.translation()) < 1e-4, weld
        assert moved.rotation().ToAngleAxis().angle() < 1e-3, weld
