"""The controller never takes a lost person for nobody (issue 52, "Planning never assumes nobody").

The body tracker is not safety-rated: it loses people behind the arm or behind each other, and
then reports an empty body (`NOBODY`). Read as it is, an empty body is "no limit" for every part
of the controller (the separation monitor, keep-clear's forecast monitor). So the tracked body
reaches the controller's parts through one memory (`BodyMemory`, between the controller's
`operator.body` input and every part that reads it): while the tracker sees someone, its reading
passes as it is (the same object); once it has seen someone and then reports nobody, the parts
read the last body seen, grown to everywhere the person could have reached since
(`grown_body`). Before anyone was seen (an empty cell from the start) an empty reading stays
empty.

The growth is ISO 13855's approach speed for the hand and arm, K = 2000 mm/s (its S = K T + C
for S <= 500 mm: `shared/reference/safety-and-devices.md`), the project's `NEAR_SPEED`
(`hrc_drake.cell.ssm`), which ISO/TS 15066 §5.5.4.2.3 takes for a person whose speed is not
monitored (`shared/reference/collaboration.md`); the larger of the standard's two speeds, for
every sphere and every distance: what the person did unseen is not known.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell.ssm import NEAR_SPEED
from hrc_drake.scenario.safety import HumanSpeed, SafetyConfig

# ISO 13855's K for the hand and arm approach [m/s] (see the module docstring).
APPROACH_SPEED = NEAR_SPEED
# The cap: a sphere grown farther than its distance from the robot's base (the world origin,
# `hrc_drake.layout`) plus this holds every point the arm, its gripper and a carried part can
# reach (the UR3 reaches 0.5 m from its base; the RG2 and a part add about 0.25 m; 1.0 m is
# above both), so growing it further changes no decision of the controller; the cap only keeps
# a long loss's figures finite. The sphere's centre stays: it never shrinks.
ARM_REACH_BOUND = 1.0  # m


@dataclass(frozen=True)
class LastSeen:
    """The last body the tracker saw and when [s]: its reading's stamp, or the controller's
    time it was read at for a reading without one."""

    body: BodySpheres
    at: float

    def __deepcopy__(self, memo) -> LastSeen:
        return self  # immutable once made (Drake copies abstract values often)


def lost_lead(config: SafetyConfig) -> float:
    """What the monitor's S_h for a body at rest falls short of a person at the approach speed
    [m]: with `safety.human_speed: tracked` it lets a hand at rest speed up at
    `hand_acceleration` (APPROACH_SPEED² / 2a: 0.067 m at 30 m/s²), but an unseen person may be
    at full speed already; with `constant` nothing (S_h is at the speed throughout)."""
    if config.human_speed == HumanSpeed.CONSTANT:
        return 0.0
    return APPROACH_SPEED * APPROACH_SPEED / (2.0 * config.hand_acceleration)


def grown_body(seen: BodySpheres, lost_for: float, lead: float = 0.0) -> BodySpheres:
    """Everywhere the person of `seen` can have reached `lost_for` s later: the same centres,
    each radius grown by APPROACH_SPEED × `lost_for` plus `lead` (`lost_lead`), at most to
    the sphere's distance from the robot's base plus ARM_REACH_BOUND (never below its own
    radius); still (zero velocities: the growth and `lead` hold the person's motion), marked
    `lost_for`."""
    centres = np.asarray(seen.centres, dtype=float)
    radii = np.asarray(seen.radii, dtype=float)
    cap = np.linalg.norm(centres, axis=1) + ARM_REACH_BOUND
    lost_for = max(lost_for, 0.0)
    grown = radii + APPROACH_SPEED * lost_for + lead
    return dataclasses.replace(
        seen,
        radii=np.maximum(np.minimum(grown, cap), radii),
        velocities=np.zeros_like(centres),
        lost_for=lost_for,
    )


def remembered(body: BodySpheres, last: LastSeen | None, now: float, lead: float = 0.0):
    """What the controller's parts read of the tracker's `body` at `now`: the reading itself
    while it holds someone, or before anyone was seen (`last` None); else the `last` body seen,
    grown over the time since (to the reading's stamp, or `now`), with the reading's stamp."""
    if len(body.radii) > 0 or last is None:
        return body
    at = now if body.stamp is None else body.stamp
    return dataclasses.replace(grown_body(last.body, at - last.at, lead), stamp=body.stamp)


class BodyMemory(LeafSystem):
    """The memory of the tracked body (see the module docstring). Input `tracked`
    (BodySpheres: the tracker's `operator.body`); output `operator.body` (BodySpheres: what the
    controller's parts read, `remembered`). Its state, the last body seen (`LastSeen`, None
    before anyone), is updated every `period` s; `config` says the monitor's S_h
    (`lost_lead`)."""

    def __init__(self, period: float, config: SafetyConfig):
        super().__init__()
        self._lead = lost_lead(config)
        self._tracked = self.DeclareAbstractInputPort("tracked", AbstractValue.Make(NOBODY))
        self._seen = self.DeclareAbstractState(AbstractValue.Make(_NOT_SEEN))
        self.DeclareAbstractOutputPort(
            "operator.body",
            lambda: AbstractValue.Make(NOBODY),
            self._calc_body,
            prerequisites_of_calc={
                self.time_ticket(),
                self.abstract_state_ticket(self._seen),
                self.input_port_ticket(self._tracked.get_index()),
            },
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def last_seen(self, context) -> LastSeen | None:
        """The last body seen, in this system's context (None: nobody yet)."""
        seen = context.get_abstract_state(self._seen).get_value()
        return None if len(seen.body.radii) == 0 else seen

    def _calc_body(self, context, output) -> None:
        body = self._tracked.Eval(context)
        output.set_value(remembered(body, self.last_seen(context), context.get_time(), self._lead))

    def _update(self, context, state) -> None:
        body = self._tracked.Eval(context)
        if len(body.radii) > 0:
            at = context.get_time() if body.stamp is None else body.stamp
            state.get_mutable_abstract_state(self._seen).set_value(LastSeen(body, at))


# The state before anyone was seen (an abstract state holds one type: a LastSeen of nobody).
_NOT_SEEN = LastSeen(NOBODY, float("-inf"))


__all__ = [
    "APPROACH_SPEED",
    "ARM_REACH_BOUND",
    "BodyMemory",
    "LastSeen",
    "grown_body",
    "lost_lead",
    "remembered",
]
