"""The occupancy rule: which parts may be in place beside a move (from the spec), how much room
the gripper and its part have among them (from the cell's geometry), the check before a run and
the layout search that suggests only layouts passing it."""

import dataclasses
from pathlib import Path

import pytest
import yaml

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.layout import layout_from
from hrc_drake.motion import check_plan
from hrc_drake.motion.ik import UnreachableError
from hrc_drake.motion.occupancy import SLACK, CellGeometry, check_occupancy, edge_room
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.reach_check import cell_geometry, check_reach
from hrc_drake.motion.reach_search import suggest_layout
from hrc_drake.motion.scene import SceneModel, load_cell_frames
from hrc_drake.resources import models_dir
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.occupancy import in_place_with, in_place_with_space
from hrc_drake.tasks.spec import load_spec

REPO = Path(__file__).resolve().parents[1]
ASSEMBLIES = models_dir() / "assemblies"
SPECS = REPO / "benchmarks" / "specs"
TWO_HOSTS = SPECS / "two-hosts.yaml"
CLEARANCE = MotionOptions().clearance


def _spec_paths() -> list[Path]:
    return sorted(ASSEMBLIES.glob("*.yaml")) + sorted(SPECS.glob("*.yaml"))


# Specs whose every pair the spec's rules allow is in some state (in the others, a pair may
# leave the remaining parts no room: only the state graph knows).
EXACT = {"flange", "four-slot", "five-slot", "three-oval", "two-hosts"}


@pytest.mark.parametrize("path", _spec_paths(), ids=lambda p: p.stem)
def test_the_spec_relation_holds_every_pair_the_state_space_holds(path):
    """Pairwise from the spec: never a pair fewer than the state graph has (the check would
    miss a neighbour); on the specs without precedence chains, none more."""
    spec = load_spec(path)
    pairwise, exact = in_place_with(spec), in_place_with_space(generate_states(spec))
    assert pairwise.keys() == exact.keys()
    assert all(pairwise[t] >= exact[t] for t in exact)
    if path.stem in EXACT:
        assert pairwise == exact


def test_precedence_and_counts_keep_parts_apart():
    spec = load_spec(ASSEMBLIES / "gearbox-cover.yaml")
    near = in_place_with(spec)
    # The breather valve goes on last: nothing is placed with it in place.
    assert not any("V3" in others for others in near.values())
    assert near["V3"] >= {"A12", "E01", "B67", "E16", "C45"}
    # One seal in each cap, the input cap's first: a seal in the input cap never has the
    # other seal in place (the output cap comes later), the output cap's has the input's.
    assert not any(token.startswith("E") for token in near["E01"])
    assert {"A12", "E01", "A23", "E03"} <= near["E15"]
    # A seal sits on its cap, which is among what is in place when it is placed.
    assert {"A12", "A23"} <= near["E02"]


def _geometry(path: Path, **layout) -> CellGeometry:
    spec = load_spec(path)
    changed = dataclasses.replace(layout_from(spec.cell), **layout)
    model = SceneModel(load_cell_frames(CellDesign.of(spec, changed)), None)
    return CellGeometry.of(model, MotionOptions())


@pytest.mark.parametrize("pitch", [0.075, 0.07])
def test_the_room_between_two_hosts_is_the_gap_between_their_plates(pitch):
    """A two-row host is pitch + 70 mm long: side by side, pitch - 70 mm apart, short of the
    clearance the planner keeps and the rule's slack (6 mm) at these pitches."""
    geometry = _geometry(TWO_HOSTS, slot_pitch=pitch)
    assert geometry.room == pytest.approx(CLEARANCE + SLACK)
    crowded = edge_room(geometry, {"S23", "F02"}, "T45", last_token="F02")
    assert crowded.near == "S23" and crowded.where == "T45"
    assert crowded.distance == pytest.approx(pitch - 0.070, abs=1e-6)
    # Undoing the host placed last meets the same neighbour.
    undo = edge_room(geometry, {"S23", "F02", "T45"}, "undo", last_token="T45")
    assert undo.near == "S23" and undo.distance == pytest.approx(crowded.distance)
    # A slot further, the hosts are a pitch further apart: room enough.
    assert edge_room(geometry, {"S12", "F01"}, "T45", last_token="F01") is None


def test_the_check_names_the_tightest_move_and_the_pitch_to_change():
    tight = _geometry(TWO_HOSTS, slot_pitch=0.07)
    breaches = check_occupancy(tight)
    assert breaches and all(b.among_seats for b in breaches)
    assert breaches[0].distance == pytest.approx(0.0, abs=1e-9)
    assert check_occupancy(_geometry(TWO_HOSTS)) == []  # the default 80 mm: 10 mm between
    # The larger specs in their own layouts (the others run through the cell in tests).
    for name in ("gearbox-cover", "valve-manifold", "pump-bracket"):
        path = next(p for p in _spec_paths() if p.stem == name)
        assert check_occupancy(_geometry(path)) == [], name


def test_the_rule_and_the_planner_agree_on_a_flange_beside_the_square():
    """At a 70 mm pitch an oval flange is 2.5 mm from the square on its neighbouring slots:
    the rule refuses the placement and the planner finds no pose for it, while it plans an
    oval flange onto the square, which the rule passes. (Every edge of small specs, at several
    pitches: benchmarks/bench_occupancy.py.)"""
    spec = load_spec()
    design = CellDesign.of(spec, dataclasses.replace(layout_from(spec.cell), slot_pitch=0.07))
    planner = MotionPlanner(MotionOptions(), design=design)
    geometry = cell_geometry(planner)
    crowded = edge_room(geometry, {"S23"}, "F1", last_token="S23")
    assert crowded.near == "S23" and crowded.distance == pytest.approx(0.0025, abs=1e-6)
    with pytest.raises(UnreachableError, match="minimum distance"):
        planner.plan_task({"S23"}, "F1", last_token="S23")
    assert edge_room(geometry, {"S12"}, "F01", last_token="S12") is None
    planner.plan_task({"S12"}, "F01", last_token="S12")


def test_a_place_with_room_plans_where_the_ik_stalled_on_its_seed():
    """Where the rule passes and planning failed without a neighbour to blame: the straight way
    down from a pre-place whose tcp the IK left exactly at its orientation tolerance, where
    SNOPT stalls (an oval flange onto the first of two hosts at a 75 mm pitch). The IK's
    second chance (`hrc_drake.motion.ik`) plans it, and the plan validates."""
    spec = load_spec(TWO_HOSTS)
    design = CellDesign.of(spec, dataclasses.replace(layout_from(spec.cell), slot_pitch=0.075))
    planner = MotionPlanner(MotionOptions(), design=design)
    assert edge_room(cell_geometry(planner), {"S12"}, "F01", last_token="S12") is None
    plan = planner.plan_task({"S12"}, "F01", last_token="S12")
    assert check_plan(plan, planner).ok


def test_the_search_never_offers_a_pitch_that_crowds_the_plate():
    """The search asks the occupancy screen before the reach check, and a pitch that crowds
    the plate is not tried again, larger ones are."""
    spec = load_spec(TWO_HOSTS)
    design = CellDesign.of(spec, dataclasses.replace(layout_from(spec.cell), slot_pitch=0.06))
    screened, checked = [], []

    def fits(candidate):
        screened.append(candidate.layout.slot_pitch)
        return "slot_pitch" if candidate.layout.slot_pitch < 0.076 else None

    def reaches(candidate):
        checked.append(candidate.layout.slot_pitch)
        return True

    found = suggest_layout(design, reaches, fits)
    assert found is not None and found.layout.slot_pitch == pytest.approx(0.08)
    assert checked == [pytest.approx(0.08)]
    assert len(set(screened)) == len(screened)  # no crowded pitch screened twice
    assert all(p < 0.076 for p in screened[:-1])


@pytest.mark.slow
def test_a_crowded_layout_is_refused_with_a_layout_that_passes(tmp_path):
    """Before: the search suggested a 55 mm pitch for a spec with two hosts, and the run
    stopped where the second host met the first. Now the check refuses it, naming the pitch,
    and suggests a layout that passes the whole check."""
    data = yaml.safe_load(TWO_HOSTS.read_text())
    data["cell"]["slot_pitch"] = 0.055
    crowded = tmp_path / "crowded.yaml"
    crowded.write_text(yaml.safe_dump(data))
    with pytest.raises(CellModelError, match=r"too tight.*cell\.slot_pitch") as err:
        check_reach(MotionPlanner(design=CellDesign.of(load_spec(crowded))))
    message = str(err.value)
    assert "the reach check passes with cell: {" in message, message
    suggestion = message.split("the reach check passes with ")[1].split(" (the spec's")[0]
    data["cell"].update(yaml.safe_load(suggestion)["cell"])
    assert data["cell"]["slot_pitch"] >= 0.076
    fixed = tmp_path / "fixed.yaml"
    fixed.write_text(yaml.safe_dump(data))
    check_reach(MotionPlanner(design=CellDesign.of(load_spec(fixed))), suggest=False)
