"""Sensor models between the simulated cell and its measured ports (`sensors:`,
`hrc_drake.scenario.sensors`): each samples what the simulator knows exactly at the device's
rate, delivers the sample its latency later, with Gaussian noise and the value quantised, and
loses a sample now and then (the reading then goes stale: the previous one stays, with its
stamp). Under `sensors: ideal` none is built (`export_measured` exports the port as it was).

`SampledVector` sits on a vector port whose first half is a value and the second its rate
(`ur3.state_estimated`: q, v; `rg2.state_measured`: opening, its rate); `SampledBody` on the
tracked body (`operator.body`: noise on the spheres' centres and velocities, radii and groups
as they are). Both output the reading and its `stamp` (the sample's time, s; NaN before the
first); the body's stamp also rides in `BodySpheres.stamp`, which the controller's separation
monitor reads for staleness.

Deterministic: the noise and dropouts come from a numpy PCG64 generator seeded from the run's
seed and the port's `seed_offset`, its state kept in the system's abstract state with the
samples waiting for delivery, so that the same seed gives the same readings and a fresh context
starts again. At the simulator's initialisation a first sample is taken and delivered at once
(the device streamed before the run began); then one every period.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem, OutputPort

from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell.scenario import plant_step
from hrc_drake.scenario.sensors import SensorModel, sensor_models

# Times within this of each other are the same instant (periodic event times are sums of
# floats).
_EPS = 1e-9


@dataclass(frozen=True)
class Sample:
    """One sample: taken at `time`, readable from `due` on."""

    time: float
    due: float
    value: Any


@dataclass(frozen=True)
class SensorState:
    """A sensor's abstract state: its generator's state (numpy's `bit_generator.state`) and
    its samples, oldest first: the newest delivered one (if any), then those still on their
    way."""

    rng: dict
    samples: tuple[Sample, ...] = ()

    def __deepcopy__(self, memo) -> SensorState:
        return self  # immutable once made (Drake copies abstract values often)

    def reading(self, now: float) -> Sample | None:
        """The newest sample delivered by `now` (None: none yet)."""
        delivered = [s for s in self.samples if s.due <= now + _EPS]
        return delivered[-1] if delivered else None


def generator_state(seed: int, offset: int) -> dict:
    """The starting state of a port's generator: PCG64 seeded with (`seed`, `offset`)."""
    return np.random.PCG64(np.random.SeedSequence([int(seed), int(offset)])).state


def quantise(values: np.ndarray, quantum: float) -> np.ndarray:
    """`values` rounded to multiples of `quantum` (0: as they are)."""
    return values if quantum <= 0 else np.round(values / quantum) * quantum


class SampledSensor(LeafSystem):
    """What both sensors share: the events, the state and the stamp (see the module
    docstring). A subclass declares its input port `input` (kept as `_input`, which `_measure`
    reads, unless the subclass reads more) and the `reading` output, and says how a sample is
    corrupted (`_corrupt`)."""

    def __init__(self, model: SensorModel, seed: int):
        super().__init__()
        self.model = model
        self._state = self.DeclareAbstractState(
            AbstractValue.Make(SensorState(generator_state(seed, model.seed_offset)))
        )
        self._prerequisites = {self.time_ticket(), self.abstract_state_ticket(self._state)}
        # One generator object, its state set from the context at each sample: making one per
        # sample seeds it from the OS first, about half of what a sample took of its own.
        self._rng = np.random.Generator(np.random.PCG64(0))
        # The state dict `_rng` was left in by this system's last sample: a context whose
        # state holds that very dict (not an equal one: the same object, never mutated) finds
        # the generator where it needs it, without setting it again.
        self._rng_left: dict | None = None
        self.DeclareVectorOutputPort(
            "stamp", BasicVector(1), self._calc_stamp, prerequisites_of_calc=self._prerequisites
        )
        self.DeclareInitializationUnrestrictedUpdateEvent(self._first)
        self.DeclarePeriodicUnrestrictedUpdateEvent(model.period, 0.0, self._sample)

    def state(self, context) -> SensorState:
        """The sensor's state in its `context`."""
        return context.get_abstract_state(self._state).get_value()

    def _corrupt(self, value, rng: np.random.Generator):
        """The reading of the true `value` as this kind of sensor gives it (noise from `rng`).
        Each subclass says it for its value's type: `SampledVector` for vectors,
        `SampledBody` for the tracked body; the base sampler is never used alone."""
        raise NotImplementedError(f"{type(self).__name__} does not say how it reads a value")

    def _measure(self, context):
        """What the sensor samples now: its input port `_input`'s value (a subclass that reads
        more says so)."""
        return self._input.Eval(context)

    def _follow(self, previous, value, now: float):
        """The sample kept for a reading `value` taken at `now`, given the `previous` sample's
        (None: none yet): the reading itself, unless a subclass carries something from frame
        to frame (the camera's verdicts)."""
        return value

    def _take(self, context, state, first: bool) -> None:
        now = context.get_time()
        old = self.state(context)
        rng = self._rng
        if old.rng is not self._rng_left:
            rng.bit_generator.state = old.rng
        self._rng_left = None  # the draws below move the generator on
        # Every sample draws its dropout and its noise, lost or not: the streams stay aligned.
        lost = rng.random() < self.model.dropout and not first
        value = self._corrupt(self._measure(context), rng)
        current = old.reading(now)
        kept = tuple(s for s in old.samples if s is current or s.due > now + _EPS)
        if not lost:
            due = now if first else now + self.model.latency
            previous = old.samples[-1].value if old.samples else None
            kept += (Sample(now, due, self._follow(previous, value, now)),)
        self._rng_left = rng.bit_generator.state
        new = SensorState(self._rng_left, kept)
        state.get_mutable_abstract_state(self._state).set_value(new)

    def _first(self, context, state) -> None:
        self._take(context, state, first=True)

    def _sample(self, context, state) -> None:
        self._take(context, state, first=False)

    def _current(self, context) -> Sample | None:
        return self.state(context).reading(context.get_time())

    def _calc_stamp(self, context, output) -> None:
        sample = self._current(context)
        output.SetAtIndex(0, float("nan") if sample is None else sample.time)


class SampledVector(SampledSensor):
    """A sensor on a vector port of `size` (even: a value, then its rate). Input `input`;
    outputs `reading` (vector `size`; zeros before the first sample) and `stamp` (1)."""

    def __init__(self, model: SensorModel, seed: int, size: int):
        super().__init__(model, seed)
        if size % 2:
            raise ValueError(f"a sampled vector holds a value and its rate: size {size} is odd")
        half = size // 2
        self._std = np.r_[np.full(half, model.noise), np.full(half, model.rate_noise)]
        self._half = half
        self._input = self.DeclareVectorInputPort("input", size)
        self.DeclareVectorOutputPort(
            "reading", size, self._calc_reading, prerequisites_of_calc=self._prerequisites
        )

    def _corrupt(self, value, rng: np.random.Generator) -> np.ndarray:
        noisy = np.asarray(value, dtype=float) + self._std * rng.standard_normal(len(self._std))
        noisy[: self._half] = quantise(noisy[: self._half], self.model.quantum)
        return noisy

    def _calc_reading(self, context, output) -> None:
        sample = self._current(context)
        output.SetFromVector(np.zeros(2 * self._half) if sample is None else sample.value)


class SampledBody(SampledSensor):
    """The body tracker's sensor. Input `input` (BodySpheres); outputs `reading` (BodySpheres
    with its `stamp`; NOBODY before the first sample) and `stamp` (1)."""

    def __init__(self, model: SensorModel, seed: int):
        super().__init__(model, seed)
        self._input = self.DeclareAbstractInputPort("input", AbstractValue.Make(NOBODY))
        self.DeclareAbstractOutputPort(
            "reading",
            lambda: AbstractValue.Make(NOBODY),
            self._calc_reading,
            prerequisites_of_calc=self._prerequisites,
        )

    def _corrupt(self, body: BodySpheres, rng: np.random.Generator) -> BodySpheres:
        n = len(body.radii)
        draws = rng.standard_normal((2, n, 3))
        centres = np.asarray(body.centres, dtype=float) + self.model.noise * draws[0]
        velocities = np.asarray(body.velocities, dtype=float) + self.model.rate_noise * draws[1]
        return dataclasses.replace(
            body, centres=quantise(centres, self.model.quantum), velocities=velocities
        )

    def _calc_reading(self, context, output) -> None:
        sample = self._current(context)
        if sample is None:
            output.set_value(NOBODY)
            return
        output.set_value(dataclasses.replace(sample.value, stamp=sample.time))


def export_measured(
    builder: DiagramBuilder,
    source: OutputPort,
    name: str,
    scenario,
    truth: OutputPort | None = None,
) -> None:
    """Export `source` as the station's measured port `name`: as it is when the `scenario`'s
    `sensors:` has no model for it (`ideal`), else through a sensor (`sensor.<name>`, seeded
    with the operator's seed, which an evaluation draws per run), exported with its stamp as
    `<name>.stamp` and the exact value as `sim.<name>` (the run's safety check scores the
    truth). `truth`: the exact value, where the device's input is not (a fault between them,
    `tracker-loss`); then `sim.<name>` is exported under `ideal` too."""
    models, seed = sensor_models(scenario.sensors), scenario.operator.seed
    model = models.get(name)
    if model is None:
        builder.ExportOutput(source, name)
        if truth is not None:
            builder.ExportOutput(truth, f"sim.{name}")
        return
    # The simulated plant keeps its step: a device faster than it (RTDE's 500 Hz over the 10 ms
    # step) would read one state several times, stamped as if newer. It samples once a step,
    # with its own latency; its stated rate is the real-time link's (`cell.link.realtime`).
    step = plant_step(scenario)
    if model.rate * step > 1.0:
        model = dataclasses.replace(model, rate=1.0 / step)
    if name == "operator.body":
        sensor = SampledBody(model, seed)
    else:
        sensor = SampledVector(model, seed, source.size())
    builder.AddNamedSystem(f"sensor.{name}", sensor)
    builder.Connect(source, sensor.GetInputPort("input"))
    builder.ExportOutput(sensor.GetOutputPort("reading"), name)
    builder.ExportOutput(sensor.GetOutputPort("stamp"), f"{name}.stamp")
    builder.ExportOutput(source if truth is None else truth, f"sim.{name}")


__all__ = [
    "Sample",
    "SampledBody",
    "SampledSensor",
    "SampledVector",
    "SensorState",
    "export_measured",
    "generator_state",
    "quantise",
]
