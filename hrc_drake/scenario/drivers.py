"""The scenario's `drivers:` section: what stands behind each device port of the cell, as Drake's
`model_drivers` says it of each model instance: the station's simulated device, or a driver for
the real one (docs/hardware.md, "Drivers as data"). Apart from `hrc_drake.scenario.schema`,
which takes `DriversConfig` as its `drivers` field.

    drivers:
      ur3: !UrRtde {host: 192.168.1.7, frequency: 500}   # an e-Series controller over RTDE
      rg2: !Rg2Modbus {host: 192.168.1.1}                 # the Compute Box over Modbus TCP

Left out, each device is `!Simulated {}`. The real drivers' values default to their settings
(`hrc_drake.drivers.settings`, the one statement of each default); `hrc-drake drivers` serves
the devices put on real hardware, and `hrc-drake station` refuses such a scenario.

Drake-free, as the loader is: the drivers themselves (Drake, pymodbus, ur_rtde) are imported by
`hrc-drake drivers` only.
"""

import dataclasses
from dataclasses import dataclass, field

from hrc_drake.drivers.settings import (
    CB3_FREQUENCY,
    E_SERIES_FREQUENCY,
    RTDE_FREQUENCIES,
    RTDE_PORT,
    Rg2Settings,
    Ur3RtdeSettings,
)


def _default(settings: type, name: str):
    """The default of the field `name` of the settings dataclass `settings`."""
    return next(f.default for f in dataclasses.fields(settings) if f.name == name)


def _hz(frequency: float) -> str:
    return f"{frequency:g} Hz"


# Plain (not frozen) dataclasses: Drake's `yaml_load_typed` sets their fields one by one.
@dataclass
class Simulated:
    """The station's simulated device (`hrc-drake station`, `hrc-drake simulate`)."""


@dataclass
class UrRtde:
    """The real UR3 over RTDE with ur_rtde (`hrc_drake.drivers.ur3_rtde`).

    Attributes:
        host: the controller's address (RTDE on its port 30004).
        frequency: RTDE's rate [Hz]: 500 on an e-Series (the cell's UR3e), 125 on a CB3.
        lookahead_time: `servoJ`'s lookahead [s], 0.03-0.2.
        gain: `servoJ`'s proportional gain, 100-2000.
    """

    host: str = ""
    frequency: float = _default(Ur3RtdeSettings, "frequency")
    lookahead_time: float = _default(Ur3RtdeSettings, "lookahead_time")
    gain: float = _default(Ur3RtdeSettings, "gain")

    def settings(self) -> Ur3RtdeSettings:
        """The driver's settings: those of the controller generation `frequency` names
        (`Ur3RtdeSettings.cb3`/`e_series`), with this lookahead and gain. ValueError for a value
        the driver cannot take, naming the key."""
        if not self.host:
            raise ValueError("host is empty: give the UR3 controller's address")
        if self.frequency == CB3_FREQUENCY:
            base = Ur3RtdeSettings.cb3(self.host)
        elif self.frequency == E_SERIES_FREQUENCY:
            base = Ur3RtdeSettings.e_series(self.host)
        else:
            rates = " or ".join(f"{f:g} ({g})" for f, g in RTDE_FREQUENCIES.items())
            raise ValueError(f"frequency {self.frequency:g} Hz is not RTDE's: give {rates}")
        return dataclasses.replace(base, lookahead_time=self.lookahead_time, gain=self.gain)

    def describe(self) -> str:
        """One line: what serves the arm, and where."""
        generation = RTDE_FREQUENCIES.get(self.frequency, "?")
        return f"UR3 over RTDE ({generation}, {_hz(self.frequency)}) at {self.host}:{RTDE_PORT}"


@dataclass
class Rg2Modbus:
    """The real RG2 through its Compute Box over Modbus TCP (`hrc_drake.drivers.rg2_modbus`).

    Attributes:
        host: the Compute Box's address.
        port: its Modbus TCP port.
        unit: the RG2's Modbus unit id.
        poll_rate: readings per second [Hz] (RG2_STATUS is published at this rate).
        timeout: seconds each Modbus request may take (and the connection at the start).
    """

    host: str = ""
    port: int = _default(Rg2Settings, "port")
    unit: int = _default(Rg2Settings, "unit")
    poll_rate: float = _default(Rg2Settings, "poll_rate")
    timeout: float = _default(Rg2Settings, "timeout")

    def settings(self) -> Rg2Settings:
        """The driver's settings; ValueError for a value the driver cannot take."""
        if not self.host:
            raise ValueError("host is empty: give the Compute Box's address")
        return Rg2Settings(self.host, self.port, self.unit, self.poll_rate, self.timeout)

    def describe(self) -> str:
        """One line: what serves the gripper, and where."""
        return f"RG2 over Modbus TCP at {self.host}:{self.port} (unit {self.unit})"


@dataclass
class DriversConfig:
    """What stands behind each device port: `ur3` (`!Simulated {}` or `!UrRtde {...}`) and
    `rg2` (`!Simulated {}` or `!Rg2Modbus {...}`)."""

    ur3: Simulated | UrRtde = field(default_factory=Simulated)
    rg2: Simulated | Rg2Modbus = field(default_factory=Simulated)

    def on_hardware(self) -> dict[str, UrRtde | Rg2Modbus]:
        """The devices put on real hardware, by name (`ur3`, `rg2`), in the section's order."""
        devices = {"ur3": self.ur3, "rg2": self.rg2}
        return {name: d for name, d in devices.items() if not isinstance(d, Simulated)}

    def check(self, key: str = "drivers") -> None:
        """ValueError naming `key.device` and the value for a real driver's value its driver
        would refuse (each real device's settings are made once here, when the scenario is
        loaded, so that `hrc-drake drivers` cannot fail on them later)."""
        for name, device in self.on_hardware().items():
            try:
                device.settings()
            except ValueError as err:
                raise ValueError(f"{key}.{name}: {err}") from None


__all__ = ["DriversConfig", "Rg2Modbus", "Simulated", "UrRtde"]
