"""The camera configuration sensor (`sensors: {configuration: camera}`): its verdicts from
estimated poses (`hrc_drake.cell.station.camera_verdicts`) on the flange cell's real seats, their
confirmation over frames, the noise they stand, their score against the contact sensor, and a
Table 2 row whose deviation the camera reads in the closed loop."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from hrc_drake.cell.ports import PartStatus
from hrc_drake.cell.run.result import RunResult
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.cell.station import make_cell_station
from hrc_drake.cell.station.camera import noisy_pose
from hrc_drake.cell.station.camera_rest import SEAT_FRAMES, SHIFT_FRAMES, rest_bound, see
from hrc_drake.cell.station.camera_score import CameraHistory, score
from hrc_drake.cell.station.camera_verdicts import (
    CONFIRM_FRAMES,
    CameraTolerances,
    follow,
    frame_placements,
    label,
    max_noise,
)
from hrc_drake.scenario.sensors import CAMERA

TOL = CameraTolerances.of(CAMERA.noise, CAMERA.angle_noise)


@pytest.fixture(scope="module")
def cell():
    """(the SlotMonitor's geometry, the plate's pose, the station) of the flange cell."""
    station = make_cell_station(load_cell_scenario("row1-optimal", LEAN))
    monitor = station.diagram.GetSubsystemByName("configuration_sensor")
    plant = station.plant
    context = plant.CreateDefaultContext()
    X_W_plate = plant.GetBodyByName("base_plate").EvalPoseInWorld(context)
    return monitor.seat_geometry(), X_W_plate, station


def _poses(station, **placed):
    """Every part at its tray home, but those `placed` (instance -> world pose)."""
    poses = dict(station.frames.homes)
    poses.update(placed)
    return poses


def _seen(cell, poses, part):
    geometry, X_W_plate, _ = cell
    return frame_placements(geometry, TOL, poses, X_W_plate, None)[part]


def test_a_part_within_tolerance_reads_seated_after_three_frames(cell):
    station = cell[2]
    seat = station.placement_poses({"oval_flange_1": "F1"})["oval_flange_1"]
    # 1 mm and 0.5 mm off, 0.3 mm high: in its pocket (1.5 mm of clearance).
    X = seat @ RigidTransform([0.001, 0.0005, 0.0003])
    verdict = follow(None, _seen(cell, _poses(station), "oval_flange_1"))
    assert verdict.reported.status == PartStatus.TRAY
    for frame in range(1, CONFIRM_FRAMES + 1):
        verdict = follow(verdict, _seen(cell, _poses(station, oval_flange_1=X), "oval_flange_1"))
        if frame < CONFIRM_FRAMES:
            assert verdict.reported.status == PartStatus.TRAY and not verdict.steady
    assert verdict.steady
    assert label(verdict.reported) == ("seated", ("slot_1",), "", "F1")


def test_a_part_in_another_slot_reads_that_slot(cell):
    station = cell[2]
    # The robot proposed F1; the part sits at slot 3: the verdict is F3, on the plate ...
    X = station.placement_poses({"oval_flange_1": "F3"})["oval_flange_1"]
    seen = _seen(cell, _poses(station, oval_flange_1=X), "oval_flange_1")
    assert (seen.status, seen.slots, seen.token) == (PartStatus.SEATED, (3,), "F3")
    # ... and on the square's row over slot 1 (the host seen where it sits, 1 mm off), F01.
    layout = station.placement_poses({"square_flange": "S12", "oval_flange_2": "F01"})
    host = layout["square_flange"] @ RigidTransform([0.001, 0.0, 0.0])
    on_host = layout["oval_flange_2"] @ RigidTransform([0.001, 0.0, 0.0])
    poses = _poses(station, square_flange=host, oval_flange_2=on_host)
    seen = _seen(cell, poses, "oval_flange_2")
    assert (seen.host, seen.slots, seen.token) == ("square_flange", (1,), "F01")


def test_noise_alone_does_not_flip_a_verdict(cell):
    """Seeded: 2000 frames of the camera's noise on a part seated in a pocket's corner, on one
    resting on a pocket's rim, and on one seated on the host part (both estimated)."""
    station = cell[2]
    layout = station.placement_poses(
        {"oval_flange_1": "F1", "square_flange": "S23", "oval_flange_2": "F02"}
    )
    corner = layout["oval_flange_1"] @ RigidTransform([0.0015, 0.0015, 0.0])
    rim = station.placement_poses({"oval_flange_1": "F1"})["oval_flange_1"] @ RigidTransform(
        RollPitchYaw(0.0, 0.01, 0.0), [0.003, 0.0, 0.004]
    )
    cases = {
        "corner": (_poses(station, oval_flange_1=corner), "oval_flange_1", ("seated", "F1")),
        "rim": (_poses(station, oval_flange_1=rim), "oval_flange_1", ("misplaced", "")),
        "host": (_poses(station, **layout), "oval_flange_2", ("seated", "F02")),
    }
    rng = np.random.default_rng(7)
    for name, (truth, part, expected) in cases.items():
        verdict = None
        for _ in range(2000):
            draws = rng.standard_normal((len(truth), 6))
            poses = {
                p: noisy_pose(X, CAMERA, d) for (p, X), d in zip(truth.items(), draws, strict=True)
            }
            verdict = follow(verdict, _seen(cell, poses, part))
            reported = (verdict.reported.status.value, verdict.reported.token or "")
            assert reported == expected, name


def _seen_over_frames(cell, truth, rng, frames, views=None):
    """The camera's views after `frames` seeded frames of its noise on the true `truth` poses
    (`camera_rest.see`), and the part verdicts it reported after each."""
    geometry, X_W_plate, _ = cell
    noise = (CAMERA.noise, CAMERA.angle_noise)
    reported = []
    for _ in range(frames):
        draws = rng.standard_normal((len(truth), 6))
        poses = {
            p: noisy_pose(X, CAMERA, d) for (p, X), d in zip(truth.items(), draws, strict=True)
        }
        views = see(geometry, TOL, noise, views, poses, X_W_plate, None)
        reported.append({p: v for p, v in views.verdicts.items()})
    return views, reported


# The square flange on 3 mm of debris under one boss, as the simulation leaves it (S23 proposed,
# `faults: [!NoSeat {task: 2, obstacle: true}]`, measured): 1.16 mm high, tilted 0.023 rad.
ON_DEBRIS = RigidTransform(RollPitchYaw(0.0, 0.023, 0.0), [0.0, 0.0, 0.00116])


def test_a_part_held_up_by_debris_is_never_read_seated(cell):
    """Before: one frame reads it seated (within the pocket's 1 mm and 0.03 rad plus the
    noise), and so did the camera. Now it is read misplaced once its frames' mean tells, and
    never seated, over 40 placements of 30 frames each (seeded)."""
    station = cell[2]
    X = station.placement_poses({"square_flange": "S23"})["square_flange"] @ ON_DEBRIS
    truth = _poses(station, square_flange=X)
    rng = np.random.default_rng(11)
    single = [
        _seen(
            cell,
            {**truth, "square_flange": noisy_pose(X, CAMERA, rng.standard_normal(6))},
            "square_flange",
        ).status
        for _ in range(200)
    ]
    assert single.count(PartStatus.SEATED) > 150  # what one frame sees
    assert rest_bound(CAMERA.noise, SEAT_FRAMES) < 0.00116 - 2 * CAMERA.noise / SEAT_FRAMES**0.5
    for _ in range(40):
        home = _seen_over_frames(cell, _poses(station), rng, 1)[0]  # in the tray, then placed
        reported = _seen_over_frames(cell, truth, rng, 30, home)[1]
        statuses = [r["square_flange"].reported.status for r in reported]
        assert PartStatus.SEATED not in statuses
        assert statuses[-1] == PartStatus.MISPLACED


def test_a_part_set_down_a_millimetre_lower_is_read_again(cell):
    """The operator takes the debris out and sets the part down in its seat, 1.16 mm lower: too
    small a move for one frame to show, it shows in the newest frames' mean (SHIFT_FRAMES), the
    older frames are dropped, and the part is read seated. Until then at most SHIFT_FRAMES - 1
    frames stand by the old verdict (a reading that says misplaced after the part was set
    down); none once the new frames are tentative (40 seeded placements)."""
    station = cell[2]
    seat = station.placement_poses({"square_flange": "S23"})["square_flange"]
    rng = np.random.default_rng(3)
    for _ in range(40):
        home = _seen_over_frames(cell, _poses(station), rng, 1)[0]
        on_debris = _poses(station, square_flange=seat @ ON_DEBRIS)
        views = _seen_over_frames(cell, on_debris, rng, 20, home)[0]
        assert views.verdicts["square_flange"].reported.status == PartStatus.MISPLACED
        reported = _seen_over_frames(cell, _poses(station, square_flange=seat), rng, 15, views)[1]
        verdicts = [r["square_flange"] for r in reported]
        seated = next(k for k, v in enumerate(verdicts) if v.reported.status == PartStatus.SEATED)
        assert seated <= SHIFT_FRAMES + SEAT_FRAMES + CONFIRM_FRAMES
        stale = [k for k, v in enumerate(verdicts[:seated]) if v.steady]
        assert stale == list(range(len(stale))) and len(stale) <= SHIFT_FRAMES


def test_a_seated_part_is_read_seated_once_its_frames_tell_and_stays_so(cell):
    """A part seated in its pocket's corner: tentative (the reading not steady) until
    SEAT_FRAMES still frames, then reported after CONFIRM_FRAMES agree; 2000 frames of noise
    flip nothing after, on the plate or on a host (seeded)."""
    station = cell[2]
    layout = station.placement_poses(
        {"oval_flange_1": "F1", "square_flange": "S23", "oval_flange_2": "F02"}
    )
    corner = layout["oval_flange_1"] @ RigidTransform([0.0015, 0.0015, 0.0])
    rng = np.random.default_rng(5)
    home = _seen_over_frames(cell, _poses(station), rng, 1)[0]
    truth = _poses(station, **{**layout, "oval_flange_1": corner})
    reported = _seen_over_frames(cell, truth, rng, 2000, home)[1]
    first = next(
        k for k, r in enumerate(reported) if r["oval_flange_1"].reported.status == PartStatus.SEATED
    )
    assert first == SEAT_FRAMES + CONFIRM_FRAMES - 2  # the frames from 1, the first frame moved
    assert not any(r["oval_flange_1"].steady for r in reported[: SEAT_FRAMES - 1])
    for part, token in (
        ("oval_flange_1", "F1"),
        ("square_flange", "S23"),
        ("oval_flange_2", "F02"),
    ):
        after = {(r[part].reported.status, r[part].reported.token) for r in reported[first + 5 :]}
        assert after == {(PartStatus.SEATED, token)}, part


def test_the_pockets_bound_the_camera_noise():
    position, angle = max_noise()
    assert CAMERA.noise <= position < 0.0004 and CAMERA.angle_noise <= angle
    text = "{sensors: {configuration: camera, camera: {noise: 0.001}}}"
    with pytest.raises(ValueError, match=r"^sensors.camera.noise: 0.001 m is more than"):
        make_cell_station(load_cell_scenario("row1-optimal", [LEAN, text]))


def test_the_score_counts_false_missed_and_wrong_slot_detections():
    f1, f3 = ("seated", ("slot_1",), "", "F1"), ("seated", ("slot_3",), "", "F3")
    tray = ("tray", (), "", "")
    history = CameraHistory()
    for k in range(20):  # 5 Hz; the part seated at F1 from 1 s, the camera late by 3 frames
        t = 0.2 * k
        truth = f1 if t >= 1.0 else tray
        history = history.add(t, {"a": truth, "b": f1}, {"a": f1 if t >= 1.6 else tray, "b": f3})
    result = score(history, grace=0.6, latency=0.15)
    # `a`: seen 0.6 s late (+ the latency); `b`: read at F3 while seated at F1 all along.
    assert result.detections == 1 and result.latencies == pytest.approx((0.75,))
    assert len(result.false_detections) == 1 and result.wrong_slot == 1
    assert len(result.missed_detections) == 1 and "b seated F1" in result.missed_detections[0]


def test_the_contact_sensors_json_has_no_configuration_key():
    result = RunResult("x", [()], ["1"], [], frozenset(), "start", False, None, [], 1.0, 1.0)
    assert "configuration" not in result.to_json()
    camera = RunResult(
        "x", [()], ["1"], [], frozenset(), "start", False, None, [], 1.0, 1.0, camera={}
    )
    assert camera.to_json()["configuration"] == {"sensor": "camera", "camera": {}}


@pytest.mark.slow
def test_the_camera_reads_the_operators_other_slot_as_contact_does():
    """Table 2 row 4, lean, with the camera: the robot proposes F1, the operator mounts F3; the
    Supervisor, which reads only the camera, sees F3, and every verdict of the camera agrees
    with the contact sensor's."""
    from hrc_drake.cell.run.run import run_scenario

    scenario = load_cell_scenario("row4-forces-4", [LEAN, "{sensors: {configuration: camera}}"])
    result = run_scenario(scenario)
    assert result.error is None and result.done and result.collisions == []
    assert [t.observed for t in result.tasks] == ["F3", "S12", "F01"]
    assert (result.tasks[0].proposed, result.tasks[0].observed) == ("F1", "F3")
    camera = result.to_json()["configuration"]["camera"]
    assert camera["detections"] == 3 and camera["wrong_slot"] == 0
    assert (camera["false_detections"], camera["missed_detections"]) == (0, 0), camera["events"]


@pytest.mark.slow
def test_the_camera_finds_a_part_held_up_by_debris_and_the_task_is_handed_over():
    """Lean row 1, the camera alone reading the cell, debris under the square flange's boss
    (S23, task 2): before, the camera read it seated (1.16 mm high) and the run went on with
    the part off its floor. Now the Supervisor finds it off its seat, places it again once, and
    hands the task over; the operator clears the pocket and the row ends in its states, with
    no wrong slot against the contact sensor."""
    from hrc_drake.cell.run.run import run_scenario

    text = (
        "{sensors: {configuration: camera}, run: {recover_tries: 1}, "
        "faults: [!NoSeat {task: 2, obstacle: true}]}"
    )
    result = run_scenario(load_cell_scenario("row1-optimal", [LEAN, text]))
    assert result.error is None and result.done and result.collisions == []
    assert [t.observed for t in result.tasks] == ["F1", "S23", "F03"]
    assert "square_flange is" in result.tasks[1].handed_over, result.events
    (record,) = result.faults
    assert record.detected_at > record.injected_at and record.recovery == "operator"
    camera = result.to_json()["configuration"]["camera"]
    assert camera["wrong_slot"] == 0 and camera["missed_detections"] == 0, camera["events"]
