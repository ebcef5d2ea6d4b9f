"""What a run reports of its faults: the scenario's entries, as the station carried them out and
as the controller found them (`simulate --json` `faults`).

The two sides never talk about faults: the station's injector says when each took effect
(`hrc_drake.cell.station.faults.Injection`, simulator only) and the Supervisor what it detected from
its measurements (`hrc_drake.cell.controller.supervisor.Detection`). A fault counts as detected by
the first detection of a cause it can produce, in its task, from its injection on.
"""

from __future__ import annotations

from collections.abc import Sequence

from hrc_drake.cell.controller.supervisor_state import Cause, Detection
from hrc_drake.cell.station.faults import Injection
from hrc_drake.hri.faults import FaultConfig, FaultKind, FaultRecord

# What each kind of fault shows as, in the controller's measurements.
CAUSES = {
    FaultKind.PROTECTIVE_STOP: {Cause.STOP},
    FaultKind.OPERATOR_SILENT: {Cause.SILENCE},
    FaultKind.PUSHED: {Cause.TRACKING},
    FaultKind.GRIPPER_STUCK: {Cause.GRIP, Cause.RELEASE},
    FaultKind.GRIP_LOST: {Cause.GRIP},
    FaultKind.NO_PATH: {Cause.PLAN},
    # Let go off its seat; pushed out of the fingers on the pocket's rim; or the arm blocked by
    # the part landing on the rim.
    FaultKind.NO_SEAT: {Cause.SEAT, Cause.GRIP, Cause.TRACKING},
    # None: the controller detects no fault; in every period it takes the person to be
    # anywhere they could have reached (`hrc_drake.cell.controller.body_memory`), and the time
    # that costs is monitoring's (`safety.monitor.ssm_delay`), not the fault's.
    FaultKind.TRACKER_LOSS: set(),
    # None either: the station's safety function takes a safeguard stop, which clears by
    # itself and which the controller does not name (`FaultRecovery.note_stop`).
    FaultKind.SAFETY_SENSOR_SILENT: set(),
}
# The recovery of a fault no cause shows: a tracker loss, ridden through under monitoring; a
# silent safety sensor, through the safety function's safeguard stop.
RIDDEN_THROUGH = {
    FaultKind.TRACKER_LOSS: "monitoring",
    FaultKind.SAFETY_SENSOR_SILENT: "safeguard stop",
}
# A detection in the same Supervisor update as the injection may carry a time a period earlier.
SLACK = 0.05  # s


def fault_records(
    faults: Sequence[FaultConfig],
    injections: Sequence[Injection],
    detections: Sequence[Detection],
    end_time: float,
) -> list[FaultRecord]:
    """One record per scenario fault. `seconds_lost` runs from the injection to the recovery
    (the cell's, or the operator's when the task was handed over and done by hand), or to the
    end of the run when nothing resolved it (0 for a fault never injected, and for a kind with
    no cause to detect: a tracker loss)."""
    records = []
    if not injections:  # a station that does not say
        injections = [Injection(f.kind.value, f.task) for f in faults]
    for fault, injection in zip(faults, injections, strict=True):
        injected = injection.injected_at
        found = next(
            (
                d
                for d in detections
                if d.cause in CAUSES[fault.kind]
                and d.step == fault.task
                and injected is not None
                and d.at >= injected - SLACK
            ),
            None,
        )
        if injected is None or not CAUSES[fault.kind]:
            lost = 0.0
        elif found is not None and found.resolved_at is not None:
            # Recovered by the cell, or by the operator's hands (a task handed over, done).
            lost = found.resolved_at - injected
        else:
            lost = end_time - injected
        recovered = found is not None and found.recovered
        recovery = found.recovery.value if found is not None and found.resolved_at else ""
        if not CAUSES[fault.kind] and injected is not None:
            # Ridden through by monitoring, not detected: over once the fault's time is up.
            recovered = injected + fault.duration <= end_time
            recovery = RIDDEN_THROUGH[fault.kind] if recovered else ""
        records.append(
            FaultRecord(
                kind=fault.kind.value,
                task=fault.task,
                injected_at=injected,
                detected_at=None if found is None else found.at,
                recovered=recovered,
                recovery=recovery,
                seconds_lost=max(lost, 0.0),
            )
        )
    return records


__all__ = ["fault_records"]
