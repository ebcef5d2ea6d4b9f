"""Which LCM channel carries which of the station's ports: each channel with its message type,
its ports in order and the conversion of their values to the message and back
(`hrc_drake.cell.link.lcm_messages`), the controller's commands (`COMMANDS`), the station's
measurements (`MEASUREMENTS`), the simulation-only touching pairs, and the session's channels.

Apart from the messages because this is the table both sides of the link walk
(`hrc_drake.cell.link.interface`, `hrc_drake.cell.link.station_server`) and the one a real
cell's driver serves (`docs/hardware.md`); the messages only say how a value is written.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, InputPort, LeafSystem

from hrc_drake.cell.link.lcm_messages import (
    N_JOINTS,
    body_message,
    body_value,
    configuration_message,
    configuration_value,
    contacts_message,
    contacts_value,
    indication_message,
    indication_value,
    lcmt_cell_configuration,
    lcmt_contacts,
    lcmt_hri_indication,
    lcmt_hri_prompt,
    lcmt_operator_body,
    lcmt_rg2_command,
    lcmt_rg2_status,
    lcmt_ur3_tcp_force,
    prompt_message,
    prompt_value,
    rg2_command,
    rg2_command_values,
    rg2_status,
    rg2_status_values,
    tcp_force_message,
    tcp_force_value,
    ur3_command,
    ur3_command_values,
    ur3_status,
    ur3_status_values,
)
from hrc_drake.cell.link.lcm_struct import LcmDecodeError
from hrc_drake.cell.ports import NOBODY, BodySpheres, CellConfiguration
from hrc_drake.hri.messages import Indication, Prompt


@dataclass(frozen=True)
class Port:
    """A station port: a vector of `size`, or an abstract value like `model()`."""

    name: str
    size: int | None = None
    model: Callable[[], object] | None = None

    def declare_input(self, system: LeafSystem) -> InputPort:
        """This port declared as an input of `system`."""
        if self.size is not None:
            return system.DeclareVectorInputPort(self.name, BasicVector(self.size))
        return system.DeclareAbstractInputPort(self.name, AbstractValue.Make(self.model()))

    def declare_output(self, system: LeafSystem, value: Callable, deps: set) -> None:
        """This port declared as an output of `system` whose value is `value(context)` (a vector
        of `size`, or an object like `model()`), computed from the `deps` tickets."""
        if self.size is not None:
            system.DeclareVectorOutputPort(
                self.name,
                BasicVector(self.size),
                lambda context, output: output.SetFromVector(value(context)),
                prerequisites_of_calc=deps,
            )
        else:
            system.DeclareAbstractOutputPort(
                self.name,
                lambda: AbstractValue.Make(self.model()),
                lambda context, output: output.set_value(value(context)),
                prerequisites_of_calc=deps,
            )


@dataclass(frozen=True)
class StationChannel:
    """An LCM channel carrying station ports: `encode(utime, *values)` makes its message from
    the ports' values, `decode(message)` gives them back (in `ports` order)."""

    channel: str
    message: type
    ports: tuple[Port, ...]
    encode: Callable[..., object]
    decode: Callable[[object], tuple]

    def stamp_of(self, data: bytes) -> int:
        """The `utime` of an encoded message (its first member, after the fingerprint)."""
        if data[:8] != self.message._get_packed_fingerprint():
            raise LcmDecodeError(
                f"{self.channel}: not a {self.message.__name__} message; both sides must use "
                "the same message definitions (the same hrc_drake version)"
            )
        return struct.unpack(">q", data[8:16])[0]


def _no_body() -> BodySpheres:
    return NOBODY


COMMANDS: tuple[StationChannel, ...] = (
    StationChannel(
        "UR3_COMMAND",
        lcmt_panda_command,
        (Port("ur3.position", N_JOINTS), Port("ur3.velocity", N_JOINTS)),
        ur3_command,
        ur3_command_values,
    ),
    StationChannel(
        "RG2_COMMAND",
        lcmt_rg2_command,
        (Port("rg2.opening", 1), Port("rg2.force", 1)),
        rg2_command,
        rg2_command_values,
    ),
    StationChannel(
        "HRI_PROMPT",
        lcmt_hri_prompt,
        (Port("hri.prompt", model=Prompt),),
        prompt_message,
        prompt_value,
    ),
)
"""What the controller commands (the station's inputs)."""

MEASUREMENTS: tuple[StationChannel, ...] = (
    StationChannel(
        "UR3_STATUS",
        lcmt_panda_status,
        (Port("ur3.state_estimated", 2 * N_JOINTS), Port("safety.stop", 1), Port("safety.mode", 1)),
        ur3_status,
        ur3_status_values,
    ),
    StationChannel(
        "UR3_TCP_FORCE",
        lcmt_ur3_tcp_force,
        (Port("ur3.tcp_force", 6),),
        tcp_force_message,
        tcp_force_value,
    ),
    StationChannel(
        "RG2_STATUS",
        lcmt_rg2_status,
        (Port("rg2.state_measured", 2), Port("rg2.grip_detected", 1)),
        rg2_status,
        rg2_status_values,
    ),
    StationChannel(
        "CELL_CONFIGURATION",
        lcmt_cell_configuration,
        (Port("configuration", model=CellConfiguration),),
        configuration_message,
        configuration_value,
    ),
    StationChannel(
        "OPERATOR_BODY",
        lcmt_operator_body,
        (Port("operator.body", model=_no_body),),
        body_message,
        body_value,
    ),
    StationChannel(
        "HRI_INDICATION",
        lcmt_hri_indication,
        (Port("hri.indication", model=Indication),),
        indication_message,
        indication_value,
    ),
)
"""What the station measures (its outputs)."""

SIM_CONTACTS = StationChannel(
    "SIM_CONTACTS",
    lcmt_contacts,
    (Port("sim.contacts", model=tuple),),
    contacts_message,
    contacts_value,
)
"""Simulation only: the touching pairs, for a run's collision watch."""

END_CHANNEL = "CELL_STATION_END"
"""The controller's session messages: its "hello" (the scenario it runs), and "end"."""
REPORT_CHANNEL = "CELL_STATION_REPORT"
"""The station's session messages: its "hello" (the scenario it serves), and its last word, its
"report" or the "error" that stopped it. (Each direction has its own channels: DrakeLcm keeps
only the newest undelivered message of a channel, and a process also hears what it publishes
itself.)"""
PRE_SUFFIX = "_PRE"
"""Lockstep: the commands as they stand just before the controller's update at a time (see
`hrc_drake.cell.link.lockstep`) go on `<channel>_PRE`."""
