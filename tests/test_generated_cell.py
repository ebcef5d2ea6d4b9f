"""The cell generated from an assembly spec: geometry, checks before simulation, and runs of new
assemblies in the physical cell that equal the decision loop's."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.geometry import SceneGraph
from pydrake.multibody.plant import MultibodyPlant

from hrc_drake.cell.run.run import shared_planner
from hrc_drake.cell_models import CellDesign, CellModelError, add_cell_models, check_cell_models
from hrc_drake.cli import main
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.reach_check import check_reach
from hrc_drake.motion.scene import load_cell_frames
from hrc_drake.resources import models_dir
from hrc_drake.tasks.spec import load_spec

ASSEMBLIES = models_dir() / "assemblies"


def _design(name: str, **layout) -> CellDesign:
    design = CellDesign.of(load_spec(ASSEMBLIES / f"{name}.yaml"))
    if layout:
        design = CellDesign.of(design.spec, dataclasses.replace(design.layout, **layout))
    return design


def test_the_flange_cell_keeps_the_papers_geometry():
    frames = load_cell_frames(_design("flange"))
    for k in (1, 2, 3):
        # Plate centre 0.30 m in front of the UR3, slots 80 mm apart along world +y.
        np.testing.assert_allclose(
            frames.seats[k].translation(), [0.30, (k - 2) * 0.08, 0.0155], atol=1e-9
        )
    np.testing.assert_allclose(frames.tray.translation(), [0.20, -0.25, 0.0], atol=1e-9)
    np.testing.assert_allclose(
        frames.homes["square_flange"].translation(), [0.13, -0.25, 0.0165], atol=1e-9
    )
    np.testing.assert_allclose(
        frames.homes["oval_flange_2"].translation(), [0.26, -0.21, 0.0165], atol=1e-9
    )
    np.testing.assert_allclose(frames.rows["S"][1].translation(), [-0.04, 0.0, 0.0165], atol=1e-9)


@pytest.mark.parametrize(("name", "slots", "parts"), [("four-slot", 4, 3), ("three-oval", 5, 4)])
def test_a_new_spec_is_a_new_cell(name, slots, parts):
    design = _design(name)
    frames = load_cell_frames(design)
    assert sorted(frames.seats) == list(range(1, slots + 1))
    assert len(frames.homes) == len(design.instance_names) == parts
    pitch = np.diff([frames.seats[k].translation()[1] for k in range(1, slots + 1)])
    np.testing.assert_allclose(pitch, 0.08)
    # The tray stands clear of the plate, whatever its length.
    plate_end = frames.seats[1].translation()[1] - 0.07
    tray_near_edge = frames.tray.translation()[1] + 0.085
    assert tray_near_edge < plate_end
    # Every home is on the tray, at least a finger's room from every other.
    homes = np.array([X.translation()[:2] for X in frames.homes.values()])
    gaps = [np.linalg.norm(a - b) for i, a in enumerate(homes) for b in homes[i + 1 :]]
    assert min(gaps) > 0.06


def test_models_that_miss_the_spec_are_refused():
    design = _design("flange")
    plant = MultibodyPlant(0.0)
    scene_graph = SceneGraph()
    plant.RegisterAsSourceForSceneGraph(scene_graph)
    add_cell_models(plant, _design("four-slot"))
    plant.Finalize()
    with pytest.raises(CellModelError, match="3 slots but the plate has 4 seat frames"):
        check_cell_models(plant, scene_graph, design)


def test_an_unreachable_slot_is_refused_before_simulation():
    # Slot 3 of a plate moved 0.35 m to the side is 0.52 m from the UR3's base axis.
    aside = _design("flange", plate_position=[0.30, 0.35, 0.0], tray_position=[0.2, -0.25, 0.0])
    planner = MotionPlanner(MotionOptions(), design=aside)
    with pytest.raises(CellModelError, match=r"cannot reach F3 \(slot 3\).*cell\.plate_position"):
        check_reach(planner)
    # Too far for the home pose above the work: refused as the planner is made.
    far = _design("flange", plate_position=[0.62, 0.0, 0.0])
    with pytest.raises(CellModelError, match=r"home pose .*cell\.plate_position"):
        MotionPlanner(MotionOptions(), design=far)


def _react(assembly: str, script: str, capsys) -> list:
    assert main(["react", "--assembly", assembly, "--operator", script, "--json"]) == 0
    return json.loads(capsys.readouterr().out)["states"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "script", "misplaced"),
    [
        # Overrides, a flange in the wrong row (seen from contact), the undo that follows.
        ("four-slot", "1:F2,3:F03", "F03"),
        # The operator undoes a correct flange, then mounts it in the other row.
        ("five-slot", "1:S45,2:F05,3:undo", None),
        # Three oval flanges: an override into a dead end, the square's wrong row, undos.
        ("three-oval", "1:F2,3:S45,4:F04", "F04"),
    ],
)
def test_new_assemblies_run_in_the_physical_cell(name, script, misplaced, capsys):
    assembly = str(ASSEMBLIES / f"{name}.yaml")
    expected = _react(assembly, script, capsys)
    code = main(["simulate", "--assembly", assembly, "--operator", script, "--lean", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out["error"]
    assert out["states"] == expected
    assert out["terminal"] is True and out["collisions"] == 0
    for step in out["steps"]:
        assert step["observed"] == step["operator"]
    if misplaced is not None:
        # The misplaced flange's state comes from the SlotMonitor's contact reading.
        assert any(s["observed"] == misplaced for s in out["steps"])
        assert [misplaced] in [s[-1:] for s in out["states"]]


def test_planner_is_shared_per_cell():
    options = MotionOptions(hold_time=0.5)
    four = _design("four-slot")
    assert shared_planner(options, four) is shared_planner(options, _design("four-slot"))
    assert shared_planner(options, four) is not shared_planner(options, _design("flange"))
