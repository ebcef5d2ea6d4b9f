"""The camera configuration sensor (`sensors: {configuration: camera}`): where each part is, as a
camera over the cell reports it — estimated part poses at a few hertz, late and noisy, now and
then a frame lost, and no contact at all.

`CameraSensor` samples the simulator's exact part poses at the camera's rate
(`hrc_drake.scenario.sensors.CAMERA`: 5 Hz, 0.15 s latency, 0.3 mm and 1 degree of noise per
axis, 2 % of frames lost), adds the noise, and decides every part's verdict from the estimated
poses alone (`hrc_drake.cell.station.camera_verdicts`: the pocket's tolerances plus three noise
standard deviations, a change reported once three frames in a row agree), a still part's from
the mean of its frames, seated only when that mean rests on the seat's floor
(`hrc_drake.cell.station.camera_rest`). It reads the plate's
pose (welded: the cell's calibration) and the gripper's tcp (the arm's kinematics) exactly; the
temporary obstacle's pose rides with the frame, late but without noise (a 100 mm box is seen
far better than a part's seat, and the controller plans again only when it moves 5 mm).

Its reading is the `configuration` port's `CellConfiguration`, each part's pose the newest
frame's estimate, and its `stamp` the newest frame whose every part's view agreed with the
verdict reported: the controller, which waits for a reading of the cell after a part came to
rest, waits for a stamp past that instant (`CellConfiguration.current_at`).

A part the operator places by hand, which the simulated station puts in its place at once, is
told to the camera (`CameraSensor.part_handled`): it starts that part's still mean again, as a
camera that saw the part lifted and set down would. Without it, a part set down by hand 1.2 mm
lower than where it had rested (on debris, cleared) was read misplaced from the old mean, its
stamp current.

The contact sensor stays the ground truth (`sim.configuration`): the camera notes its verdict
beside it at every frame (`hrc_drake.cell.station.camera_score.CameraHistory`) and the run
scores it (`CameraSensor.score`: false and missed detections, the detection latency).
Deterministic as the other sensors: the noise and losses come from a PCG64 generator seeded
with the run's seed and the camera's `seed_offset`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell.ports import CellConfiguration, placement_transform, pose_tuple
from hrc_drake.cell.station.camera_rest import CameraViews, rotation_from_vector, see
from hrc_drake.cell.station.camera_score import CameraHistory, CameraScore, Label, score
from hrc_drake.cell.station.camera_verdicts import CONFIRM_FRAMES, CameraTolerances, label
from hrc_drake.cell.station.sensors import SampledSensor
from hrc_drake.cell.station.slot_monitor import SeatGeometry, SlotMonitor
from hrc_drake.scenario.sensors import SensorModel, camera_model


@dataclass(frozen=True)
class CameraFrame:
    """One frame: every part's estimated world pose, the plate's and the tcp's pose (None: no
    robot), the obstacle seen, and the truth's verdict on each part at the frame."""

    poses: dict[str, RigidTransform]
    X_W_plate: RigidTransform
    X_W_tcp: RigidTransform | None
    obstacle: tuple[float, ...]
    truth: dict[str, Label]


@dataclass(frozen=True)
class CameraReading:
    """What the camera keeps from frame to frame: the reading it delivers, each part's
    verdict and still estimates, and its history beside the truth."""

    configuration: CellConfiguration
    views: CameraViews
    history: CameraHistory

    def __deepcopy__(self, memo) -> CameraReading:
        return self  # immutable once made (Drake copies abstract values often)


def noisy_pose(X: RigidTransform, model: SensorModel, draw: np.ndarray) -> RigidTransform:
    """The camera's estimate of the pose `X` for six standard normal draws: `model.noise`
    times the first three added to the position, the orientation turned by the rotation vector
    `model.angle_noise` times the last three (world axes)."""
    R = rotation_from_vector(model.angle_noise * np.asarray(draw[3:])) @ X.rotation()
    return RigidTransform(R, X.translation() + model.noise * np.asarray(draw[:3]))


class CameraSensor(SampledSensor):
    """The camera (module docstring). Inputs: `truth` (the contact sensor's CellConfiguration:
    the exact pose of every part, the obstacle), `body_poses` (the plant's). Outputs: `reading`
    (CellConfiguration, stamped; empty before the first frame) and `stamp` (the newest frame's
    time).

    Args:
        model: the camera's rate, latency, noise (`noise` m, `angle_noise` rad), dropout.
        seed: the run's seed.
        geometry: the cell's seats, homes and grasps (`SlotMonitor.seat_geometry`).
    """

    def __init__(self, model: SensorModel, seed: int, geometry: SeatGeometry):
        super().__init__(model, seed)
        self._geometry = geometry
        self._tolerances = CameraTolerances.of(model.noise, model.angle_noise)
        self._parts = tuple(sorted(geometry.symbols))
        self.DeclareAbstractInputPort("truth", AbstractValue.Make(CellConfiguration()))
        self.DeclareAbstractInputPort("body_poses", AbstractValue.Make([RigidTransform()]))
        self.DeclareAbstractOutputPort(
            "reading",
            lambda: AbstractValue.Make(CellConfiguration()),
            self._calc_reading,
            prerequisites_of_calc=self._prerequisites,
        )

    def _measure(self, context):
        return self.GetInputPort("truth").Eval(context), self.GetInputPort("body_poses").Eval(
            context
        )

    def _corrupt(self, value, rng: np.random.Generator) -> CameraFrame:
        truth, poses = value
        geometry = self._geometry
        draws = rng.standard_normal((len(self._parts), 6))
        estimated = {}
        for part, draw in zip(self._parts, draws, strict=True):
            X = placement_transform(truth.placement(part))
            estimated[part] = noisy_pose(X, self.model, draw)
        X_W_tcp = None
        if geometry.tcp is not None:
            body, X_BT = geometry.tcp
            X_W_tcp = poses[body] @ X_BT
        return CameraFrame(
            estimated,
            poses[geometry.plate_body],
            X_W_tcp,
            truth.obstacle,
            {part: label(p) for part, p in truth.placements},
        )

    def _follow(self, previous: CameraReading | None, frame: CameraFrame, now: float):
        noise = (self.model.noise, self.model.angle_noise)
        views = see(
            self._geometry,
            self._tolerances,
            noise,
            previous.views if previous is not None else None,
            frame.poses,
            frame.X_W_plate,
            frame.X_W_tcp,
        )
        verdicts = views.verdicts
        steady = all(v.steady for v in verdicts.values())
        stamp = now if steady or previous is None else previous.configuration.stamp
        placements = tuple(
            (p, replace(verdicts[p].reported, pose=pose_tuple(frame.poses[p]))) for p in self._parts
        )
        history = previous.history if previous is not None else CameraHistory()
        history = history.add(now, frame.truth, {p: label(v.reported) for p, v in verdicts.items()})
        return CameraReading(CellConfiguration(placements, frame.obstacle, stamp), views, history)

    def _calc_reading(self, context, output) -> None:
        sample = self._current(context)
        output.set_value(CellConfiguration() if sample is None else sample.value.configuration)

    def part_handled(self, context, part: str) -> None:
        """The operator took `part` in hand (simulator only: the station puts a part placed
        by hand in its place at once, where a camera would see it lifted and set down): in
        this system's mutable `context`, its still estimates go, so that its next frames
        start a new mean, and a seated look at it is tentative until they tell, as after
        any move (`hrc_drake.cell.station.camera_rest`)."""
        state = self.state(context)
        if not state.samples:
            return
        last = state.samples[-1]
        reading: CameraReading = last.value
        stills = {p: still for p, still in reading.views.stills.items() if p != part}
        handled = replace(reading, views=replace(reading.views, stills=stills))
        samples = (*state.samples[:-1], replace(last, value=handled))
        context.get_mutable_abstract_state(self._state).set_value(replace(state, samples=samples))

    def history(self, context) -> CameraHistory:
        """The camera's verdicts beside the truth's, up to its newest frame, in its `context`."""
        samples = self.state(context).samples
        return samples[-1].value.history if samples else CameraHistory()

    def score(self, context) -> CameraScore:
        """The camera's verdicts scored against the truth so far (`camera_score.score`)."""
        grace = CONFIRM_FRAMES / self.model.rate
        return score(self.history(context), grace, self.model.latency)


CAMERA_SYSTEM = "sensor.configuration"


def export_configuration(builder: DiagramBuilder, monitor: SlotMonitor, plant, scenario) -> None:
    """Export the station's `configuration` port: the contact sensor's reading (`monitor`'s)
    as it is, or, with `sensors: {configuration: camera}`, the camera's (`sensor.configuration`,
    seeded with the operator's seed), with its frame's time as `configuration.stamp` and the
    contact sensor's, the ground truth, as `sim.configuration`."""
    truth = monitor.GetOutputPort("slot_configuration")
    model = camera_model(scenario.sensors)
    if model is None:
        builder.ExportOutput(truth, "configuration")
        return
    camera = builder.AddNamedSystem(
        CAMERA_SYSTEM, CameraSensor(model, scenario.operator.seed, monitor.seat_geometry())
    )
    builder.Connect(truth, camera.GetInputPort("truth"))
    builder.Connect(plant.get_body_poses_output_port(), camera.GetInputPort("body_poses"))
    builder.ExportOutput(camera.GetOutputPort("reading"), "configuration")
    builder.ExportOutput(camera.GetOutputPort("stamp"), "configuration.stamp")
    builder.ExportOutput(truth, "sim.configuration")


__all__ = [
    "CAMERA_SYSTEM",
    "CameraFrame",
    "CameraReading",
    "CameraSensor",
    "export_configuration",
    "noisy_pose",
]
