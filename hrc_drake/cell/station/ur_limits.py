"""The UR's own limits as the station's safety function enforces them (`safety.limits`,
`hrc_drake.cell.robot_limits`): what puts the robot in reduced mode by itself (its trigger
plane), the watch on the measured arm that ends in a protective stop, and the path control's cap
on a command that would break the limit set in force (`hrc_drake.cell.station.safety_motion`)."""

from __future__ import annotations

import numpy as np

from hrc_drake.cell.ports import SafetyMode
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.robot_limits import LimitPoints, active_limits, beyond_plane, exceeded
from hrc_drake.cell.station.safety_motion import Cap, chase
from hrc_drake.scenario.safety import RobotLimitsConfig


class UrLimits:
    """The limits of `config` on the robot of `envelope`, judged every `period` s."""

    def __init__(self, envelope: RobotEnvelope, config: RobotLimitsConfig, period: float):
        self._points, self._config, self._period = LimitPoints(envelope), config, period

    def triggered(self, q: np.ndarray, opening: float) -> bool:
        """Whether the TCP at the measured `q` lies past the reduced-mode trigger plane."""
        config = self._config
        if not config.enabled or config.reduced_plane is None:
            return False
        return beyond_plane(config, self._points.tcp(q, opening))

    def watch(self, state, q, v, opening: float, now: float):
        """(since when a limit has been broken, None: it is not; the words of a limit broken for
        the detection time, None: none) for the measured arm (`q`, `v`) in the safety
        function's `state` (its `mode`, `reduced_since`, `over_since`): judged by the normal
        set until reduced mode has held for its transition; not while stopped."""
        config = self._config
        if not config.enabled or state.mode.stopped:
            return None, None
        settled = now >= state.reduced_since + config.transition - 1e-9
        judged = active_limits(config, state.mode == SafetyMode.REDUCED and settled)
        words = exceeded(self._points.reading(q, v, opening), judged, config.tolerance)
        if words is None:
            return None, None
        since = now if state.over_since is None else state.over_since
        return since, (words if now >= since + config.detection_time - 1e-9 else None)

    def cap(self, cap: Cap | None, reduced: bool, q_cmd, v_cmd, q, opening, now: float):
        """The path control's cap for the next period on the command (`q_cmd`, `v_cmd`) under
        the set in force (None: the command keeps within it), its speeds judged by the
        kinematics of the measured arm at `q` (the servo's target lies within millimetres of
        it, and the watch has posed it already)."""
        if not self._config.enabled:
            return None
        active = active_limits(self._config, reduced)

        def scale(v) -> float:
            return self._points.scale(q, v, opening, active)

        return chase(cap, q_cmd, v_cmd, now, self._period, scale)


__all__ = ["UrLimits"]
