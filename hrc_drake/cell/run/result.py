"""What a closed-loop run did (`RunResult`), read from the diagram's outputs when it ends, and
its JSON (the `--json` of `hrc-drake simulate`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hrc_drake.cell.controller.separation import SafetyLog
from hrc_drake.cell.controller.supervisor import TaskRecord
from hrc_drake.cell.run.safety_check import SafetyCheck
from hrc_drake.cell.station.safety_function import SafetyFunctionLog
from hrc_drake.hri.faults import FaultRecord

if TYPE_CHECKING:
    from hrc_drake.cell.link.realtime import RealtimeFigures


@dataclass(frozen=True)
class RunResult:
    """What a closed-loop run did, read from the diagram's outputs."""

    scenario: str
    states: list[tuple[str, ...]]
    names: list[str]
    tasks: list[TaskRecord]
    final_tokens: frozenset[str]
    final_kind: str
    done: bool
    error: str | None
    collisions: list[str]
    sim_time: float
    wall_time: float
    recording: Path | None = None
    events: tuple[str, ...] = field(default_factory=tuple)
    safety: SafetyLog | None = None
    """Separation monitoring figures (None: the scenario has no operator body)."""
    safety_check: SafetyCheck | None = None
    """The run's own check of separation (`hrc_drake.cell.run.safety_check`; None: no body)."""
    safety_function: SafetyFunctionLog | None = None
    """What the station's safety function did (None: a station that does not say)."""
    speed_changes: tuple[tuple[float, str], ...] = ()
    """(simulated time, "moving" | "slowed" | "stopped") each time the robot's speed state
    changes (with the operator body)."""
    interrupted: bool = False
    """The run was ended by Ctrl-C before it finished."""
    faults: tuple[FaultRecord, ...] = ()
    """The scenario's faults: when injected, detected, and what came of them."""
    interaction: str = ""
    """The interaction mode the robot ran in: `anticipate` or `wait`."""
    separation: str = ""
    """The separation mode: `predictive` or `reactive` (`SafetyConfig.separation`)."""
    waited: float = 0.0
    """Seconds the robot waited where it planned to, for the operator (predictive)."""
    replans: int = 0
    """Times the robot re-timed its plan because the body departed from its forecast."""
    capped: bool = False
    """The run ended by its own task cap (`run.max_steps`), its reason in `error`."""
    camera: dict | None = None
    """The camera configuration sensor's verdicts scored against the contact sensor's
    (`sensors: {configuration: camera}`; `hrc_drake.cell.station.camera_score`); None: the
    contact sensor."""
    realtime: RealtimeFigures | None = None
    """How the controller kept its pace over the real-time link (None: in one process or in
    the lockstep)."""

    @property
    def idle(self) -> tuple[float, ...]:
        """Per task: simulated seconds the robot waited on the planner after the indication."""
        return tuple(t.idle for t in self.tasks)

    @property
    def wall_idle(self) -> tuple[float, ...]:
        """Per task: the same wait in wall-clock seconds (the machine's planning time)."""
        return tuple(t.wall_idle for t in self.tasks)

    @property
    def handovers(self) -> int:
        """Tasks the robot handed over and the operator did by hand."""
        return sum(1 for t in self.tasks if t.handed_over)

    @property
    def plan_ready(self) -> tuple[bool, ...]:
        """Per task: the plan was ready (planned ahead) when the operator indicated."""
        return tuple(t.plan_ready for t in self.tasks)

    @property
    def real_time_factor(self) -> float | None:
        """Simulated time over wall time."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else None

    def to_json(self) -> dict:
        """A JSON-able summary (the `--json` of `hrc-drake simulate`)."""
        rtf = self.real_time_factor
        return {
            "scenario": self.scenario,
            "states": [list(s) for s in self.states],
            "names": self.names,
            "terminal": bool(self.done),
            "final_kind": self.final_kind,
            "final_configuration": sorted(self.final_tokens),
            "collisions": len(self.collisions),
            "contacts": list(self.collisions),
            "steps": [_step_json(t) for t in self.tasks],
            "mean_idle": round(float(np.mean(self.idle)), 4) if self.tasks else 0.0,
            "wall_mean_idle": round(float(np.mean(self.wall_idle)), 4) if self.tasks else 0.0,
            "error": self.error,
            "capped": self.capped,
            "interrupted": self.interrupted,
            "sim_time": round(self.sim_time, 3),
            "wall_time": round(self.wall_time, 3),
            "real_time_factor": None if rtf is None else round(rtf, 3),
            "recording": str(self.recording) if self.recording else None,
            "safety": self._safety_json(),
            "faults": [f.to_json() for f in self.faults],
            "handovers": self.handovers,
            "interaction": self.interaction,
            "separation": self.separation,
            # Only with a camera: the contact sensor's runs print what they always did.
            **({} if self.camera is None else {"configuration": self._configuration_json()}),
            "realtime": None if self.realtime is None else self.realtime.to_json(),
        }

    def _configuration_json(self) -> dict:
        """The configuration sensor and the camera's score (with a camera only)."""
        return {"sensor": "camera", "camera": self.camera}

    def _safety_json(self) -> dict | None:
        """The run's safety in three: `check` (the run's own, `SafetyCheck`, and its `summary`
        in words at the top), `function` (the station's safety function) and `monitor` (the
        controller's planning figures, with predictive mode's planned waits and re-timings)."""
        if self.safety is None:
            return None
        check = self.safety_check
        function = self.safety_function
        monitor = self.safety.to_json()
        monitor.update(planned_wait=round(self.waited, 3), replans=self.replans)
        return {
            "summary": None if check is None else check.summary(),
            "check": None if check is None else check.to_json(),
            "function": None if function is None else function.to_json(),
            "monitor": monitor,
        }


def _step_json(t: TaskRecord) -> dict:
    return {
        "step": t.step,
        "proposed": t.proposed,
        "operator": t.indicated,
        "observed": t.observed,
        "part": t.part,
        "sim_time": round(t.end_time - t.start_time, 3),
        "idle_time": round(t.idle, 4),
        "wall_idle_time": round(t.wall_idle, 4),
        "plan_ready": t.plan_ready,
        "committed": t.committed,
        "indicated_at": None if t.indicated_at is None else round(t.indicated_at, 3),
        "held_at": None if t.held_at is None else round(t.held_at, 3),
        "retargeted": t.retargeted,
        "swapped": t.swapped,
        "handed_over": bool(t.handed_over),
        "handover_reason": t.handed_over or None,
    }


__all__ = ["RunResult"]
