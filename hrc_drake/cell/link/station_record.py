"""What a simulated station knows beside its ports, sent to the controller's process with the
session's report (`hrc_drake.cell.link.station_server`, `hrc_drake.cell.link.remote`): its fault
injector's record and its safety function's log, which a one-process run reads straight from the
station (`hrc_drake.cell.run.loop.LocalCell`) for the run's `faults` and `safety.function`.

The report is the `text` of the station's `report` session message, JSON:

    {"sim_time": 12.34, "exchanges": 1234,
     "injected": [Injection.to_json(), ...],
     "safety_function": SafetyFunctionLog.to_json() or null}

With a camera for the configuration (`sensors: {configuration: camera}`) the report also holds
`"camera"`: its verdicts scored against the contact sensor's
(`hrc_drake.cell.station.camera_score.CameraScore.to_json`); without one the key is absent.

`injected` has one entry per scenario fault, in the scenario's order
(`hrc_drake.cell.station.faults.Injection`: kind, task, task_start, injected_at, since, ended_at,
shifted, target); `safety_function` is null for a station without the robot. A station that
keeps no such record (a real cell's driver, a test's stand-in) sends neither key, and the run
reads it as a station that does not say (no fault injected, no safety function's log).
"""

from __future__ import annotations

from dataclasses import dataclass

from pydrake.systems.framework import Context

from hrc_drake.cell.link.lockstep import StationLinkError
from hrc_drake.cell.station.faults import Injection
from hrc_drake.cell.station.safety_function import SafetyFunctionLog


@dataclass(frozen=True)
class StationRecord:
    """A simulated station's fault record and safety function's log at the end of a session."""

    injected: tuple[Injection, ...] = ()
    safety_function: SafetyFunctionLog | None = None
    camera: dict | None = None  # the camera's score (JSON), None without a camera

    @staticmethod
    def of(station, root: Context) -> StationRecord:
        """The record of `station` (a `CellStation`) in the `root` context, as a one-process run
        reads it (its `sim.faults` output, its safety function's state)."""
        context = station.diagram.GetMyContextFromRoot(root)
        injected = station.diagram.GetOutputPort("sim.faults").Eval(context)
        state = station.safety_function_state(root)
        camera = station.camera_score(root)
        return StationRecord(
            tuple(injected),
            None if state is None else state.log,
            None if camera is None else camera.to_json(),
        )

    def to_json(self) -> dict:
        """The report's `injected` and `safety_function` keys, and `camera` with a camera (see
        the module docstring)."""
        function = self.safety_function
        report = {
            "injected": [i.to_json() for i in self.injected],
            "safety_function": None if function is None else function.to_json(),
        }
        if self.camera is not None:
            report["camera"] = self.camera
        return report

    @staticmethod
    def from_report(report: dict) -> StationRecord | None:
        """The record in a station's session `report` (None: the station keeps none);
        StationLinkError if the report carries one that cannot be read."""
        if "injected" not in report:
            return None
        try:
            function = report["safety_function"]
            return StationRecord(
                tuple(Injection.from_json(i) for i in report["injected"]),
                None if function is None else SafetyFunctionLog.from_json(function),
                report.get("camera"),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise StationLinkError(
                f"the cell station's report has a fault record or safety log this controller "
                f"cannot read ({type(err).__name__}: {err}); both sides must run the same "
                "hrc_drake version"
            ) from None


__all__ = ["StationRecord"]
