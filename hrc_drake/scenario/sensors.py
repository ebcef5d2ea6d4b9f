"""The scenario's `sensors:` section: how each measured device port of the station reads what
it measures — its rate, latency, noise, quantisation and dropout (docs/station.md, "Sensor
models"). Apart from `hrc_drake.scenario.schema`, which takes it as its `sensors` field.

    sensors: ideal                     # the default: every measurement exact, at every step
    sensors: realistic                 # the devices' figures below
    sensors: {preset: realistic, body: {latency: 0.1, dropout: 0.05}}   # a preset, overridden
    sensors: {preset: realistic, configuration: camera}                # a camera for the parts

The measured ports modelled, by key: `ur3` (`ur3.state_estimated`: joint positions [rad], then
velocities [rad/s]), `rg2` (`rg2.state_measured`: opening [m], then its rate [m/s]), `body`
(`operator.body`: sphere centres [m], then their velocities [m/s]) and `wrench`
(`ur3.tcp_force`: the wrist load's force [N], then its moment [N·m]). Each reading is a value and
its rate of change, so a model has one noise for each (`noise`, `rate_noise`) and quantises the
value only (an encoder's or a register's step; the rate is derived from it); the wrench's two
halves are its force and its moment, so there `noise` is the force's [N] and `rate_noise` the
moment's [N·m].

Under `ideal` the station inserts nothing: its diagram is the one it always was. A port left
ideal in a mapping over `ideal` stays so; a port given there starts from an exact sensor and
needs its `rate`.

`configuration` chooses the configuration sensor (the `configuration` port): `contact` (the
default: the simulator's contact with the seat floors and its exact body poses) or `camera`
(part poses estimated with a camera's noise, rate and latency, the verdicts taken from the
poses alone; `hrc_drake.cell.station.camera`). The camera reads with its own figures (`CAMERA`,
overridden under `camera:`) whatever the preset, which says how the other ports read: an exact
camera is what `contact` already is. Drake-free, as the loader is.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from enum import StrEnum


class ConfigurationSensor(StrEnum):
    """`sensors.configuration`: what reads where the parts are."""

    CONTACT = "contact"  # the simulator's contacts and exact poses (the ground truth)
    CAMERA = "camera"  # noisy part poses at a camera's rate and latency, no contact


class Preset(StrEnum):
    """`sensors` (or `sensors.preset`): the sensors' figures before any override."""

    IDEAL = "ideal"  # exact readings at every step: nothing inserted in the station
    REALISTIC = "realistic"  # the devices' rates, latencies, noise and steps (below)


# The measured ports a sensor model may sit on, by the section's key.
PORTS = {
    "ur3": "ur3.state_estimated",
    "rg2": "rg2.state_measured",
    "body": "operator.body",
    "wrench": "ur3.tcp_force",
}


@dataclass(frozen=True)
class SensorModel:
    """How one measured port reads: a sample every 1/`rate` s, delivered `latency` s later,
    with Gaussian noise, its value quantised, and dropped with probability `dropout` (a dropped
    sample leaves the previous reading, which goes stale).

    Attributes:
        rate: samples per second [Hz].
        latency: seconds from a sample to its reading at the port.
        noise: standard deviation of the value's noise (rad, m: the port's unit; the camera's
            on each coordinate of a part's position).
        rate_noise: standard deviation of the rate's noise (rad/s, m/s).
        angle_noise: standard deviation of an orientation's noise about each axis [rad] (the
            camera's; the vector ports have none).
        quantum: the value's resolution (0: none); the value is rounded to a multiple of it.
        dropout: probability that a sample is lost, in [0, 1).
        max_latency: the latency's bound [s] (at least `latency`): a reader treats a reading
            older than one period plus this as stale.
        seed_offset: added to the run's seed for this port's noise and dropouts.
    """

    rate: float
    latency: float = 0.0
    noise: float = 0.0
    rate_noise: float = 0.0
    quantum: float = 0.0
    dropout: float = 0.0
    max_latency: float = 0.0
    seed_offset: int = 0
    angle_noise: float = 0.0

    @property
    def period(self) -> float:
        """Seconds between samples."""
        return 1.0 / self.rate

    @property
    def stale_after(self) -> float:
        """The age [s] past which a reading is stale: one period plus the latency's bound
        (a reading is between `latency` and `latency + period` old while none is lost)."""
        return self.period + self.latency_bound

    @property
    def latency_bound(self) -> float:
        """The longest a reading takes to arrive [s]: `max_latency`, at least `latency`."""
        return max(self.latency, self.max_latency)


# The `realistic` preset, the one statement of its figures (docs/station.md cites them):
REALISTIC = {
    # UR3e: RTDE streams `actual_q`/`actual_qd` at 500 Hz on an e-Series (RTDE guide;
    # docs/hardware.md, "UR3: RTDE"); latency one RTDE period (our assumption: the controller's
    # cycle). Sampled from the plant's 10 ms step, the samples between two steps repeat. Joint
    # encoder step 1e-4 rad (*assumption*: the class of UR's absolute encoders; UR publishes
    # the arm's ±0.1 mm repeatability, not the step). Velocity noise 1e-3 rad/s and no lost
    # samples on the wired RTDE link (*assumptions*).
    "ur3": SensorModel(
        rate=500.0,
        latency=0.002,
        rate_noise=1e-3,
        quantum=1e-4,
        max_latency=0.002,
        seed_offset=1,
    ),
    # RG2: the width register counts 1/10 mm (docs/hardware.md's register map, register 267),
    # polled at 25 Hz (the driver's default; *assumption*: 10-50 Hz, issue 31), read 10 ms
    # after the poll (*assumption*: a Modbus TCP round trip), 1% of the polls lost
    # (*assumption*); the rate from successive readings, 1 mm/s of noise (*assumption*).
    "rg2": SensorModel(
        rate=25.0,
        latency=0.01,
        rate_noise=1e-3,
        quantum=1e-4,
        dropout=0.01,
        max_latency=0.02,
        seed_offset=2,
    ),
    # Body tracker: a depth camera with skeleton tracking at about 30 Hz, 50-100 ms latency
    # (75 ms taken; 100 ms the bound) and centimetre noise (issue 31; docs/hardware.md, "Body
    # tracker"); its velocities filtered to 5 cm/s of noise and 1% of frames lost (occlusion)
    # (*assumptions*).
    "body": SensorModel(
        rate=30.0,
        latency=0.075,
        noise=0.01,
        rate_noise=0.05,
        dropout=0.01,
        max_latency=0.1,
        seed_offset=3,
    ),
    # The wrist load (`ur3.tcp_force`): a UR e-Series's force/torque sensor in the tool flange,
    # RTDE's `actual_TCP_force`, zeroed before a guarded move as a UR program does with
    # `zero_ftsensor()` (so no bias is modelled). Sampled with the arm's state, at RTDE's 500 Hz
    # and one period late; 1 N and 0.05 N·m of noise (*assumption*: of the order of the precision UR
    # states for the UR3e's sensor, a few newtons; a CB3 estimates the load from its joint
    # currents, about ±10 N, too coarse for the guarded descent's 8 N, docs/station.md).
    "wrench": SensorModel(
        rate=500.0,
        latency=0.002,
        noise=1.0,
        rate_noise=0.05,
        max_latency=0.002,
        seed_offset=5,  # 4 is the camera's
    ),
}

# The camera of `configuration: camera`, the one statement of its figures (docs/station.md cites
# them). A camera over the plate estimating each part's 6-DoF pose: issue 31 asks for "a
# camera's pose estimates with millimetre/degree noise at a few hertz".
CAMERA = SensorModel(
    # A few hertz: a learned segmentation and pose pipeline on an RGB-D camera runs at 2-4
    # frames per second with CUDA (bowu1004/instance_segmentation_RealSense: Mask R-CNN on a
    # RealSense D435); a model- or fiducial-based estimate somewhat faster: 5 Hz (*assumption*).
    rate=5.0,
    # Exposure, transfer and the estimate: 0.15 s, bounded by 0.2 s (*assumptions*).
    latency=0.15,
    max_latency=0.2,
    # 0.3 mm per coordinate: sub-millimetre, the class Intel states for its short-range
    # RealSense D405 (7-50 cm, "sub-millimeter accuracy"); the exact figure is ours. It is also
    # about what the pockets allow a single frame (hrc_drake.cell.station.camera_verdicts:
    # at most 0.35 mm, to tell a seated part from one on a pocket's rim at 3 sigma).
    noise=0.0003,
    # 1 degree about each axis: issue 31's "degree" (*assumption*).
    angle_noise=0.0175,
    # 2% of the frames lost: the arm or the operator's hands between the camera and the plate
    # (*assumption*).
    dropout=0.02,
    seed_offset=4,
)

PRESETS: dict[str, dict[str, SensorModel]] = {
    Preset.IDEAL.value: {},
    Preset.REALISTIC.value: REALISTIC,
}


# Plain (not frozen) dataclasses: the YAML loaders set their fields one by one.
@dataclass
class SensorSettings:
    """One port's overrides (`sensors.<port>`): each field left out (None) is the preset's."""

    rate: float | None = None
    latency: float | None = None
    noise: float | None = None
    rate_noise: float | None = None
    quantum: float | None = None
    dropout: float | None = None
    max_latency: float | None = None
    seed_offset: int | None = None
    angle_noise: float | None = None

    def given(self) -> dict[str, float | int]:
        """The fields given, by name."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


@dataclass
class SensorsConfig:
    """`sensors:` as a mapping: a `preset` and per-port overrides (see the module docstring)."""

    preset: str = Preset.IDEAL.value
    ur3: SensorSettings = field(default_factory=SensorSettings)
    rg2: SensorSettings = field(default_factory=SensorSettings)
    body: SensorSettings = field(default_factory=SensorSettings)
    wrench: SensorSettings = field(default_factory=SensorSettings)
    configuration: str = ConfigurationSensor.CONTACT.value
    camera: SensorSettings = field(default_factory=SensorSettings)


Sensors = SensorsConfig | str


def _check_model(model: SensorModel, key: str) -> None:
    """ValueError naming `key.field` for a value no sensor can have."""

    def bad(name: str, problem: str) -> ValueError:
        return ValueError(f"{key}.{name}: {problem}, got {getattr(model, name)}")

    if not (math.isfinite(model.rate) and model.rate > 0):
        raise bad("rate", "give samples per second > 0")
    for name in ("latency", "noise", "rate_noise", "quantum", "max_latency", "angle_noise"):
        value = getattr(model, name)
        if not (math.isfinite(value) and value >= 0):
            raise bad(name, "give a finite value >= 0")
    if not 0.0 <= model.dropout < 1.0:
        raise bad("dropout", "give a probability in [0, 1)")


def sensor_models(sensors: Sensors, key: str = "sensors") -> dict[str, SensorModel]:
    """The sensor model of each port that is not ideal, by station port name
    (`ur3.state_estimated`, ...); empty under `ideal`. ValueError in one line naming the key for
    an unknown preset or a value no sensor can have."""
    preset = sensors if isinstance(sensors, str) else sensors.preset
    where = key if isinstance(sensors, str) else f"{key}.preset"
    if preset not in PRESETS:
        raise ValueError(f"{where}: unknown preset {preset!r}; use {' or '.join(PRESETS)}")
    base = PRESETS[preset]
    models = {}
    for name, port in PORTS.items():
        model = base.get(name)
        given = {} if isinstance(sensors, str) else getattr(sensors, name).given()
        if given and model is None:
            if "rate" not in given:
                raise ValueError(
                    f"{key}.{name}: give its rate [Hz]: under the {preset} preset the port "
                    "has no sensor to override"
                )
            model = SensorModel(rate=given["rate"], seed_offset=list(PORTS).index(name) + 1)
        if model is None:
            continue
        models[port] = _overridden(model, given, f"{key}.{name}")
    camera_model(sensors, key)  # the configuration sensor's keys are checked with the rest
    return models


def _overridden(model: SensorModel, given: dict, key: str) -> SensorModel:
    """`model` with the fields `given`, checked (ValueError naming `key.field`)."""
    model = dataclasses.replace(model, **given)
    if "latency" in given and "max_latency" not in given:
        model = dataclasses.replace(model, max_latency=max(model.max_latency, model.latency))
    _check_model(model, key)
    if model.max_latency < model.latency:
        raise ValueError(
            f"{key}.max_latency: the bound must be >= latency {model.latency}, "
            f"got {model.max_latency}"
        )
    return model


def configuration_sensor(sensors: Sensors, key: str = "sensors") -> ConfigurationSensor:
    """Which configuration sensor the section chooses (`contact` for a preset's name);
    ValueError in one line naming `key.configuration` and the choices for another value."""
    if isinstance(sensors, str):
        return ConfigurationSensor.CONTACT
    try:
        return ConfigurationSensor(sensors.configuration)
    except ValueError:
        choices = " or ".join(c.value for c in ConfigurationSensor)
        raise ValueError(
            f"{key}.configuration: unknown sensor {sensors.configuration!r}; use {choices}"
        ) from None


def camera_model(sensors: Sensors, key: str = "sensors") -> SensorModel | None:
    """The camera's model (`CAMERA` with the section's `camera:` overrides) when the section
    chooses `configuration: camera`, else None. ValueError in one line naming the key for a
    bad choice, a value no camera can have, or `camera:` figures given to the contact sensor."""
    choice = configuration_sensor(sensors, key)
    given = {} if isinstance(sensors, str) else sensors.camera.given()
    if choice == ConfigurationSensor.CONTACT:
        if given:
            raise ValueError(
                f"{key}.camera: figures for a camera, but {key}.configuration is contact; "
                "add configuration: camera"
            )
        return None
    return _overridden(CAMERA, given, f"{key}.camera")


__all__ = [
    "CAMERA",
    "PORTS",
    "PRESETS",
    "REALISTIC",
    "ConfigurationSensor",
    "Preset",
    "SensorModel",
    "SensorSettings",
    "Sensors",
    "SensorsConfig",
    "camera_model",
    "configuration_sensor",
    "sensor_models",
]
