"""The separation monitor per call (`bench_separation.py --study monitor`): the controller's
monitor's inputs recorded at every call in a run, and replayed through it and through the
SceneGraph monitor it replaced (`scene_graph_monitor.SeparationMonitor`), side by side.

Calls are timed in the process's CPU time: on a shared machine wall time also counts the time
other jobs hold the core.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

# The baseline beside this module (benchmarks/ is on the path when the benchmark runs).
import scene_graph_monitor
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.separation import ControllerSeparationMonitor, assess
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN, cell_design, load_cell_scenario, motion_options
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.robot_models import RG2_MAX_OPENING, set_rg2_opening
from hrc_drake.robot_names import UR3_JOINTS
from hrc_drake.scenario.load import table2_scenarios
from hrc_drake.tasks.spec import load_spec

_clock = time.process_time


@dataclass(frozen=True)
class Sample:
    """The controller's monitor's inputs at one call, and what the call cost in the run."""

    q: np.ndarray
    v: np.ndarray
    opening: float | None
    body: BodySpheres
    intent: MotionIntent
    seconds: float
    cpu: float


class Recorder:
    """Wraps the controller's monitor's reading: records its inputs and times each call."""

    def __init__(self):
        self.samples: list[Sample] = []
        self.inputs_cpu = 0.0
        self._reading = ControllerSeparationMonitor._calc_reading

    def __enter__(self):
        recorder = self

        def reading(monitor, context, output):
            # The inputs first (untimed here): evaluating them computes the station's side
            # (the body's spheres, the measured ports) on demand.
            start = _clock()
            x = np.array(monitor.GetInputPort("ur3.state_estimated").Eval(context))
            gripper = monitor.GetInputPort("rg2.state_measured")
            opening = float(gripper.Eval(context)[0]) if gripper.HasValue(context) else None
            body = monitor.GetInputPort("operator.body").Eval(context)
            intent = monitor.GetInputPort("intent").Eval(context)
            recorder.inputs_cpu += _clock() - start
            start, cpu = time.perf_counter(), _clock()
            recorder._reading(monitor, context, output)
            seconds, cpu = time.perf_counter() - start, _clock() - cpu
            n = len(UR3_JOINTS)
            recorder.samples.append(Sample(x[:n], x[n:], opening, body, intent, seconds, cpu))

        ControllerSeparationMonitor._calc_reading = reading
        return self

    def __exit__(self, *exc):
        ControllerSeparationMonitor._calc_reading = self._reading


@dataclass(frozen=True)
class _Grasp:
    kind: str
    part: str


@dataclass(frozen=True)
class _Commanded:
    """What the SceneGraph monitor reads of the Supervisor's status: the grasp welds and (in
    `_SceneGraphMonitor`) the plan's velocity at full speed."""

    qdot: np.ndarray
    welds: frozenset = field(default_factory=frozenset)


class _SceneGraphMonitor(scene_graph_monitor.SeparationMonitor):
    """The SceneGraph monitor, its plan velocity taken from the recorded MotionIntent."""

    def _nominal_qdot(self, status, now):
        return status.qdot


class ReplayedMonitor:
    """The SceneGraph monitor in a diagram with the full cell (`make_cell_station`), fed the
    recorded inputs."""

    def __init__(self, scenario, design, acceleration):
        station = make_cell_station(scenario)
        builder = DiagramBuilder()
        cell = builder.AddSystem(station.diagram)
        robot = [station.instances["ur3"], station.instances["rg2"]]
        parts = {name: station.instances[name] for name in design.instance_names}
        config, period = scenario.safety, scenario.run.period
        self.monitor = builder.AddSystem(
            _SceneGraphMonitor(
                station.plant, station.scene_graph, robot, parts, config, acceleration, period
            )
        )
        builder.Connect(
            cell.GetOutputPort("sim.plant_state"), self.monitor.GetInputPort("plant_state")
        )
        builder.Connect(
            cell.GetOutputPort("sim.query_object"), self.monitor.GetInputPort("query_object")
        )
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.station, self.plant, self.robot = station, station.plant, robot
        self.plant_context = station.plant.GetMyMutableContextFromRoot(self.context)
        self.monitor_context = self.monitor.GetMyMutableContextFromRoot(self.context)
        self.scene_context = station.scene_graph.GetMyContextFromRoot(self.context)

    def _pose(self, sample: Sample) -> None:
        """The plant as measured: arm, fingers, and the carried part at its grasp."""
        plant, context = self.plant, self.plant_context
        plant.SetPositions(context, self.robot[0], sample.q)
        plant.SetVelocities(context, self.robot[0], sample.v)
        opening = RG2_MAX_OPENING / 2 if sample.opening is None else sample.opening
        set_rg2_opening(plant, context, opening, self.robot[1])
        part = sample.intent.carrying
        if part is not None:
            X_W_tcp = plant.GetFrameByName("tcp", self.robot[1]).CalcPoseInWorld(context)
            body = plant.get_body(plant.GetBodyIndices(self.station.instances[part])[0])
            X_W_part = X_W_tcp @ self.station.frames.grasps[part].inverse()
            plant.SetFreeBodyPose(context, body, X_W_part)

    def call(self, sample: Sample):
        """(reading, seconds) of one call; the SceneGraph's poses are updated before timing."""
        self._pose(sample)
        part = sample.intent.carrying
        welds = frozenset({_Grasp("grasp", part)}) if part is not None else frozenset()
        status = _Commanded(np.asarray(sample.intent.qdot), welds)
        self.monitor.GetInputPort("body").FixValue(self.monitor_context, sample.body)
        self.monitor.GetInputPort("status").FixValue(self.monitor_context, status)
        query = self.station.scene_graph.get_query_output_port().Eval(self.scene_context)
        query.ComputeSignedDistanceToPoint(np.full(3, 9.0), 0.0)  # the pose update
        start = _clock()
        reading = self.monitor.GetOutputPort("reading").Eval(self.monitor_context)
        return reading, _clock() - start


def _controller_call(monitor, context, sample: Sample):
    monitor.GetInputPort("ur3.state_estimated").FixValue(
        context, np.concatenate([sample.q, sample.v])
    )
    if sample.opening is not None:
        monitor.GetInputPort("rg2.state_measured").FixValue(context, [sample.opening, 0.0])
    monitor.GetInputPort("operator.body").FixValue(context, sample.body)
    monitor.GetInputPort("intent").FixValue(context, sample.intent)
    start = _clock()
    reading = monitor.GetOutputPort("reading").Eval(context)
    return reading, _clock() - start


def _stats(seconds) -> tuple[float, float, float]:
    """(median, p99, mean) in µs."""
    us = 1e6 * np.asarray(seconds)
    return float(np.median(us)), float(np.percentile(us, 99)), float(np.mean(us))


def replay(samples, scenario, design, acceleration, repeat):
    """Both monitors over the recorded samples, `repeat` times (the fastest pass per call):
    (times of the SceneGraph one, of the controller's, of `assess`), (their readings)."""
    replaced = ReplayedMonitor(scenario, design, acceleration)
    ours = ControllerSeparationMonitor(design, scenario.safety, acceleration, scenario.run.period)
    context = ours.CreateDefaultContext()
    old_t = np.full(len(samples), np.inf)
    new_t, pure_t = old_t.copy(), old_t.copy()
    old_r, new_r = [None] * len(samples), [None] * len(samples)
    for _ in range(repeat):
        for k, s in enumerate(samples):
            old_r[k], t = replaced.call(s)
            old_t[k] = min(old_t[k], t)
            new_r[k], t = _controller_call(ours, context, s)
            new_t[k] = min(new_t[k], t)
            start = _clock()
            assess(
                ours.envelope, s.q, s.v, s.body, s.intent, scenario.safety, acceleration, s.opening
            )
            pure_t[k] = min(pure_t[k], _clock() - start)
    return (old_t, new_t, pure_t), (old_r, new_r)


def agreement(old_r, new_r) -> list[str]:
    """The readings' agreement, as lines of the report."""
    old_sep = np.array([r.separation for r in old_r])
    new_sep = np.array([r.separation for r in new_r])
    near = np.isfinite(old_sep) & (old_sep < scene_graph_monitor.EXACT)
    diff = new_sep[near] - old_sep[near]
    old_lim = np.array([r.limit for r in old_r])
    new_lim = np.array([r.limit for r in new_r])
    differ = np.abs(new_lim - old_lim) > 1e-6
    return [
        f"- Least separation where the SceneGraph monitor is exact "
        f"(< {scene_graph_monitor.EXACT} m, "
        f"{int(near.sum())} calls): the controller's minus it from {diff.min() * 1e3:+.2f} to "
        f"{diff.max() * 1e3:+.2f} mm (median {np.median(diff) * 1e3:+.2f} mm)."
        if near.any()
        else "- The body never came within the SceneGraph monitor's exact range.",
        f"- Speed limit: differs by more than 1e-6 in {int(differ.sum())} of {len(old_r)} calls; "
        f"least limit {old_lim.min():.3f} (SceneGraph) and {new_lim.min():.3f} (controller's); "
        f"calls below 1: {int((old_lim < 1).sum())} and {int((new_lim < 1).sum())}.",
        f"- Least separation over the run: {np.nanmin(old_sep):.4f} m (SceneGraph) and "
        f"{new_sep.min():.4f} m (controller's).",
    ]


def report_lines(command: str, full: bool, repeat: int, name, run, samples, times) -> list[str]:
    """The report's lines up to the readings' agreement: the run (`command` wrote it, `full` or
    lean settings, `repeat` replay passes), the times per call, each monitor's share."""
    result, cpu, period, inputs_cpu = run
    old, new, pure = (_stats(t) for t in times)
    spheres = np.mean([len(s.body.radii) for s in samples])
    carrying = np.mean([s.intent.carrying is not None for s in samples])
    settings = "full (5 s holds)" if full else "lean (0.5 s holds)"
    return [
        "# The separation monitor per call: the controller's against the SceneGraph one",
        "",
        f"Command: `{command}`. Settings: {settings}. "
        f"Run: {name}, {result.sim_time:.1f} s simulated in {result.wall_time:.1f} s wall, "
        f"{cpu:.1f} s of CPU (plan cache warm). The machine's two cores may be shared with other "
        "jobs, so calls are timed in CPU time and shares are given in CPU time; the ratio is "
        "the figure to read.",
        "",
        f"{len(samples)} calls recorded (one per Supervisor step of {1e3 * period:.0f} ms), "
        f"{spheres:.0f} body spheres each, a part carried in {100 * carrying:.0f} % of them; "
        f"replayed {repeat}× through both monitors (the fastest pass per call kept).",
        "",
        "| monitor | median [µs] | p99 [µs] | mean [µs] |",
        "|---|---|---|---|",
        f"| SceneGraph (`scene_graph_monitor.SeparationMonitor`) | {old[0]:.0f} | "
        f"{old[1]:.0f} | {old[2]:.0f} |",
        f"| controller's (`separation.ControllerSeparationMonitor`, port Eval) | {new[0]:.0f} | "
        f"{new[1]:.0f} | {new[2]:.0f} |",
        f"| controller's `assess` alone | {pure[0]:.0f} | {pure[1]:.0f} | |",
        "",
        f"Ratio SceneGraph / controller's: {old[0] / new[0]:.1f}× at the median, "
        f"{old[1] / new[1]:.1f}× at p99, {old[2] / new[2]:.1f}× in the mean.",
        "",
        "## Share of the run (CPU time)",
        "",
        *_shares(result, cpu, samples, old[2] * 1e-6),
        f"- Evaluating the monitor's inputs in the run (the station computes the body's spheres "
        f"and the measured ports on demand): {inputs_cpu:.2f} s, {100 * inputs_cpu / cpu:.1f} %; "
        "not counted above.",
        "",
    ]


def _shares(result, cpu: float, samples, old_call: float) -> list[str]:
    """The controller's monitor's share of the run as timed in it, and the SceneGraph one's in
    its place (the rest of the run unchanged)."""
    spent, wall = sum(s.cpu for s in samples), sum(s.seconds for s in samples)
    rest, old_total = cpu - spent, len(samples) * old_call
    return [
        f"- The controller's monitor in the run: {spent:.2f} s of {cpu:.1f} s, "
        f"{100 * spent / cpu:.1f} % ({wall:.2f} s of {result.wall_time:.1f} s wall, "
        f"{100 * wall / result.wall_time:.1f} %); {result.sim_time / cpu:.2f} simulated seconds "
        "per CPU second (the real-time factor on a core of its own).",
        f"- The SceneGraph monitor in its place ({len(samples)} × {1e6 * old_call:.0f} µs): "
        f"{old_total:.2f} s of {rest + old_total:.1f} s, "
        f"{100 * old_total / (rest + old_total):.1f} %; "
        f"{result.sim_time / (rest + old_total):.2f} simulated seconds per CPU second.",
    ]


def measure(row: int, full: bool, repeat: int, command: str) -> str:
    """The report of Table 2 row `row` (lean unless `full`) recorded in one run and replayed
    `repeat` times through both monitors; `command` wrote it."""
    name = next(r.name for r in table2_scenarios() if r.table2_row == row)
    texts = None if full else LEAN
    run_scenario(name, scenario_text=texts)  # warms the plan cache: the timed run plans nothing
    with Recorder() as recorder:
        cpu = time.process_time()
        result = run_scenario(name, scenario_text=texts)
        cpu = time.process_time() - cpu
    scenario = load_cell_scenario(name, texts)
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    acceleration = motion_options(scenario).joint_acceleration_limit
    samples = recorder.samples
    times, readings = replay(samples, scenario, design, acceleration, repeat)
    run = (result, cpu, scenario.run.period, recorder.inputs_cpu)
    lines = report_lines(command, full, repeat, name, run, samples, times)
    lines += ["## Agreement of the readings", "", *agreement(*readings), ""]
    return "\n".join(lines)
