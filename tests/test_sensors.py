"""Sensor models on the station's measured ports (`sensors:`): the section's presets, overrides
and refusals, and the sampled sensor itself in a tiny diagram (rate, latency, noise,
quantisation, dropout, determinism)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from hrc_drake.cell.controller.separation import BodyAge, reading_age, stale_reading
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.station.sensors import SampledBody, SampledVector, export_measured, quantise
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.scenario.sensors import REALISTIC, SensorModel, sensor_models


class Ramp(LeafSystem):
    """A value t and its rate 1 (a vector of 2: value, rate)."""

    def __init__(self):
        super().__init__()
        self.DeclareVectorOutputPort("y", 2, lambda c, o: o.SetFromVector([c.get_time(), 1.0]))


def _sensor(model: SensorModel, seed: int = 0, source=None):
    builder = DiagramBuilder()
    source = builder.AddSystem(source if source is not None else Ramp())
    sensor = builder.AddSystem(SampledVector(model, seed, 2))
    builder.Connect(source.get_output_port(0), sensor.GetInputPort("input"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    return simulator, sensor, context


def _readings(model: SensorModel, times, seed: int = 0, source=None):
    """(reading, stamp) at each of `times`."""
    simulator, sensor, context = _sensor(model, seed, source)
    out = []
    for t in times:
        simulator.AdvanceTo(t)
        out.append(
            (
                sensor.GetOutputPort("reading").Eval(context).copy(),
                float(sensor.GetOutputPort("stamp").Eval(context)[0]),
            )
        )
    return out


def test_output_updates_at_the_rate_and_arrives_latency_late():
    model = SensorModel(rate=10.0, latency=0.25)
    times = np.arange(0.0, 1.0, 0.01)
    stamps = [stamp for _, stamp in _readings(model, times)]
    # The first sample is delivered at once; then each sample k/10 is read from k/10 + 0.25.
    for t, stamp in zip(times, stamps, strict=True):
        expected = 0.0 if t < 0.25 - 1e-9 else np.floor((t - 0.25) * 10 + 1e-6) / 10
        assert stamp == pytest.approx(expected, abs=1e-9), t
    values = [reading[0] for reading, _ in _readings(model, times)]
    assert values == pytest.approx([max(0.0, s) for s in stamps])  # the ramp's value at the stamp
    assert len(set(stamps)) == 8  # 0, then 0.1 ... 0.7 by t = 0.99


def test_noise_has_its_standard_deviation_and_the_rate_its_own():
    model = SensorModel(rate=100.0, noise=0.01, rate_noise=0.5)
    source = ConstantVectorSource([1.0, 0.0])
    times = np.arange(0.005, 20.0, 0.01)
    readings = np.array([reading for reading, _ in _readings(model, times, source=source)])
    assert np.std(readings[:, 0]) == pytest.approx(0.01, rel=0.1)
    assert np.mean(readings[:, 0]) == pytest.approx(1.0, abs=0.002)
    assert np.std(readings[:, 1]) == pytest.approx(0.5, rel=0.1)


def test_the_value_is_quantised_and_its_rate_not():
    model = SensorModel(rate=50.0, quantum=0.003)
    readings = _readings(model, np.arange(0.01, 1.0, 0.02))
    for reading, _ in readings:
        assert reading[0] / 0.003 == pytest.approx(round(reading[0] / 0.003), abs=1e-9)
        assert reading[1] == 1.0
    assert quantise(np.array([0.0051]), 0.0) == pytest.approx([0.0051])


def test_a_dropped_sample_keeps_the_old_value_and_its_old_stamp():
    model = SensorModel(rate=100.0, dropout=0.3)
    times = np.arange(0.005, 3.0, 0.01)  # between samples: each sees the newest delivered
    readings = _readings(model, times)
    stale = 0
    for (reading, stamp), t in zip(readings, times, strict=True):
        assert reading[0] == pytest.approx(stamp)  # the value belongs to its stamp
        stale += t - stamp > 0.01
    assert 0.2 * len(times) < stale < 0.4 * len(times)  # about 30 % of the samples lost


def test_the_same_seed_gives_the_same_readings_and_another_seed_others():
    model = SensorModel(rate=100.0, noise=0.01, dropout=0.1)
    times = np.arange(0.005, 0.5, 0.01)

    def run(seed):
        return np.array([np.r_[r, s] for r, s in _readings(model, times, seed=seed)])

    first = run(3)
    assert np.array_equal(first, run(3))
    assert not np.array_equal(first, run(4))
    other = dataclasses.replace(model, seed_offset=1)
    offset = [np.r_[r, s] for r, s in _readings(other, times, 3)]
    assert not np.array_equal(first, np.array(offset))


def test_a_fresh_context_starts_the_sensor_again():
    model = SensorModel(rate=100.0, noise=0.01)
    simulator, sensor, _ = _sensor(model)
    simulator.AdvanceTo(0.3)
    first = sensor.state(sensor.GetMyContextFromRoot(simulator.get_context()))
    simulator, sensor, _ = _sensor(model)
    simulator.AdvanceTo(0.3)
    again = sensor.state(sensor.GetMyContextFromRoot(simulator.get_context()))
    assert [s.value.tolist() for s in first.samples] == [s.value.tolist() for s in again.samples]
    fresh = sensor.CreateDefaultContext()
    assert sensor.state(fresh).samples == ()


class _Body(LeafSystem):
    def __init__(self, body: BodySpheres):
        super().__init__()
        self.DeclareAbstractOutputPort(
            "body", lambda: AbstractValue.Make(body), lambda c, o: o.set_value(body)
        )


def test_the_body_reading_is_noisy_late_and_stamped():
    body = BodySpheres(np.ones((4, 3)), np.full(4, 0.05), np.zeros((4, 3)), ((0, 4),))
    model = SensorModel(rate=30.0, latency=0.075, noise=0.01, rate_noise=0.05, max_latency=0.1)
    builder = DiagramBuilder()
    source = builder.AddSystem(_Body(body))
    sensor = builder.AddSystem(SampledBody(model, 0))
    builder.Connect(source.get_output_port(0), sensor.GetInputPort("input"))
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.2)
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    reading = sensor.GetOutputPort("reading").Eval(context)
    assert reading.stamp == pytest.approx(3 / 30)  # 3/30 + 0.075 <= 0.2 < 4/30 + 0.075
    assert reading.radii.tolist() == body.radii.tolist() and reading.groups == body.groups
    assert 0 < np.abs(reading.centres - body.centres).max() < 0.06
    assert 0 < np.abs(reading.velocities).max() < 0.3
    age = BodyAge(stale_after=model.stale_after)
    assert reading_age(reading, 0.2) == pytest.approx(0.1)
    assert not stale_reading(reading, 0.2, age)
    assert stale_reading(reading, reading.stamp + 1 / 30 + 0.1 + 0.001, age)
    assert not stale_reading(dataclasses.replace(reading, stamp=None), 100.0, age)


def test_the_presets_and_their_overrides_parse():
    assert sensor_models(load_scenario("row1-optimal").sensors) == {}
    realistic = sensor_models(load_scenario("row1-optimal", "{sensors: realistic}").sensors)
    assert set(realistic) == {
        "ur3.state_estimated",
        "ur3.tcp_force",
        "rg2.state_measured",
        "operator.body",
    }
    assert realistic["ur3.state_estimated"] == REALISTIC["ur3"]
    assert realistic["ur3.state_estimated"].rate == 500.0
    assert realistic["operator.body"].latency == 0.075
    text = "{sensors: {preset: realistic, body: {latency: 0.09, dropout: 0.0}}}"
    body = sensor_models(load_scenario("row1-optimal", text).sensors)["operator.body"]
    assert (body.latency, body.dropout, body.rate) == (0.09, 0.0, 30.0)
    only = sensor_models(load_scenario(None, "{sensors: {rg2: {rate: 10}}}").sensors)
    assert list(only) == ["rg2.state_measured"] and only["rg2.state_measured"].noise == 0.0


@pytest.mark.parametrize(
    "text, named",
    [
        ("{sensors: real}", "sensors: unknown preset 'real'; use ideal or realistic"),
        ("{sensors: {preset: exact}}", "sensors.preset: unknown preset 'exact'"),
        ("{sensors: {body: {rat: 3}}}", "sensors.body.rat: unknown key"),
        ("{sensors: {body: {latency: 0.1}}}", "sensors.body: give its rate [Hz]"),
        ("{sensors: {preset: realistic, rg2: {dropout: 1.0}}}", "sensors.rg2.dropout"),
        ("{sensors: {preset: realistic, ur3: {rate: 0}}}", "sensors.ur3.rate"),
        ("{sensors: {preset: realistic, ur3: {noise: -1}}}", "sensors.ur3.noise"),
        (
            "{sensors: {preset: realistic, body: {max_latency: 0.01}}}",
            "sensors.body.max_latency: the bound must be >= latency",
        ),
        (
            "{sensors: {configuration: cam}}",
            "sensors.configuration: unknown sensor 'cam'; use contact or camera",
        ),
        ("{sensors: {camera: {rate: 3}}}", "sensors.camera: figures for a camera, but"),
        ("{sensors: {configuration: camera, camera: {angle_noise: -1}}}", "sensors.camera.angle"),
    ],
)
def test_a_malformed_section_is_refused_in_one_line(text, named):
    with pytest.raises(ScenarioError) as err:
        load_scenario("row1-optimal", text)
    message = str(err.value)
    assert named in message and "\n" not in message


@pytest.mark.parametrize("preset", ["ideal", "realistic"])
def test_ideal_inserts_nothing_and_realistic_a_sensor_with_its_stamp(preset):
    scenario = load_scenario("row1-optimal", f"{{sensors: {preset}}}")
    builder = DiagramBuilder()
    source = builder.AddSystem(Ramp())  # a value and its rate, as rg2.state_measured
    export_measured(builder, source.get_output_port(0), "rg2.state_measured", scenario)
    diagram = builder.Build()
    ports = [diagram.get_output_port(i).get_name() for i in range(diagram.num_output_ports())]
    if preset == "ideal":
        assert ports == ["rg2.state_measured"] and len(diagram.GetSystems()) == 1
    else:
        assert ports == ["rg2.state_measured", "rg2.state_measured.stamp", "sim.rg2.state_measured"]
        assert diagram.HasSubsystemNamed("sensor.rg2.state_measured")


@pytest.mark.slow
def test_row_1_runs_to_its_end_with_realistic_sensors_and_the_camera():
    """One lean run with `sensors: realistic` and the camera for the configuration: late, noisy,
    quantised readings that are now and then lost, part verdicts from noisy poses alone, and
    the cell still ends terminal in its states, without a collision, every verdict of the
    camera backed by the contact sensor's and none missed."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = "{sensors: {preset: realistic, configuration: camera}}"
    result = run_scenario(load_cell_scenario("row1-optimal", [LEAN, text]))
    assert result.error is None, result.error
    assert result.done and result.final_kind == "terminal"
    assert result.collisions == []
    assert result.names == list(load_scenario("row1-optimal").minimum_effort)
    assert result.safety.violations == 0 and result.safety.body_contacts == 0
    # The run's check allows for the tracker's response: T_r 0.1 s and its 1/30 s period and
    # 0.1 s latency bound.
    assert result.safety_check.reaction_time == pytest.approx(0.1 + 1 / 30 + 0.1)
    assert result.safety_check.passed
    camera = result.camera
    assert camera["detections"] == 3 and camera["frames"] > 100
    assert (camera["false_detections"], camera["missed_detections"]) == (0, 0), camera["events"]


@pytest.mark.parametrize(
    "text",
    [
        "{}",
        "{sensors: realistic}",
        "{sensors: {preset: realistic, body: {rate: 15}}}",
        "{sensors: {configuration: camera, camera: {rate: 3}}}",
    ],
)
def test_drakes_loader_reads_the_section_as_ours(text):
    from pydrake.common.yaml import yaml_load_typed

    from hrc_drake.scenario.schema import Scenario

    drakes = yaml_load_typed(schema=Scenario, data=text, defaults=Scenario()).sensors
    assert drakes == load_scenario(None, text).sensors
