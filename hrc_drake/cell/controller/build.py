"""The cell's controller: the Supervisor and its separation monitor, as one diagram whose ports
are exactly what a real cell offers (`docs/station.md`).

Inputs (measured): `ur3.state_estimated`, `ur3.tcp_force`, `rg2.state_measured`,
`rg2.grip_detected`, `configuration`, `operator.body`, `hri.indication`. Outputs (commanded):
`ur3.position`, `ur3.velocity`, `rg2.opening`, `rg2.force`, `hri.prompt`; and `status` (the
Supervisor's, for whoever runs the controller: progress lines, the stack light, reports). The
planner runs beside it, behind a `PlanService` (`hrc_drake.motion.service`). Built the same
whether the station is the simulated one in this process (`make_cell_station`) or one served
over LCM.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder

from hrc_drake.cell.controller.body_memory import BodyMemory
from hrc_drake.cell.controller.forecast import OperatorForecast, forecast_body
from hrc_drake.cell.controller.guard import GuardSettings
from hrc_drake.cell.controller.keep_clear import KeepClearSettings
from hrc_drake.cell.controller.separation import (
    MONITOR_LAG,
    BodyAge,
    ControllerSeparationMonitor,
    SafetyLog,
    planned_limit,
)
from hrc_drake.cell.controller.supervisor import (
    ARM_PORTS,
    Supervisor,
    SupervisorLimits,
    TaskRecord,
)
from hrc_drake.cell.person import desk_of
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope
from hrc_drake.cell.robot_limits import PlanLimits
from hrc_drake.cell.separation_pipeline import (
    FORECAST_POSES_KEPT,
    SeparationPipeline,
    pipeline_of,
)
from hrc_drake.cell.ssm import NEAR_SPEED, planning_settings, stopping_time
from hrc_drake.cell_models import CellDesign
from hrc_drake.motion.clearance import ScaleFn, remembered
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.scene import load_cell_frames
from hrc_drake.motion.service import PlanService
from hrc_drake.scenario.safety import SafetyConfig, Separation
from hrc_drake.scenario.schema import Activity, Scenario
from hrc_drake.scenario.sensors import PORTS, sensor_models
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.policy import Policy

MEASURED = (
    "ur3.state_estimated",
    "ur3.tcp_force",
    "rg2.state_measured",
    "rg2.grip_detected",
    "safety.stop",
    "safety.mode",
    "configuration",
    "operator.body",
    "hri.indication",
)
COMMANDED = (*ARM_PORTS, "hri.prompt")
# What a station may measure beside its ports: the command the arm followed when measured
# (RTDE's `target_q`: the simulated station's and the real-time link's; the lockstep does not
# carry it) and whether an arm or body reading is stale (the real-time link's,
# `hrc_drake.cell.link.realtime`). Unconnected where the station has no such port.
LINK_READINGS = ("ur3.target", "link.stale")
# What the robot takes from a person rather than from its controller (a UR's pendant).
PENDANT = ("safety.unlock",)
# What the robot takes from the link that carries its commands: 1 while they have stopped coming
# (the real-time link's watchdog, `hrc_drake.cell.link.realtime`); unconnected, never.
WATCHDOG = ("ur3.command_stale",)


@dataclass(frozen=True)
class Controller:
    """The built controller: its diagram, its Supervisor, and its separation monitor (None when
    the scenario has no operator body to keep clear of)."""

    diagram: Diagram
    supervisor: Supervisor
    monitor: ControllerSeparationMonitor | None

    def safety_log(self, root_context) -> SafetyLog | None:
        """The separation monitor's log in a root context (None without a monitor)."""
        if self.monitor is None:
            return None
        return self.monitor.log(self.monitor.GetMyContextFromRoot(root_context))


def supervisor_limits(scenario: Scenario, options: MotionOptions) -> SupervisorLimits:
    """The Supervisor's timing and checks from the scenario's `run:` and `station:`."""
    run, station = scenario.run, scenario.station
    return SupervisorLimits(
        period=run.period,
        settle_time=run.settle_time,
        max_steps=run.max_steps,
        joint_acceleration=options.joint_acceleration_limit,
        tracking_tolerance=station.ur3.tracking_tolerance,
        grip_tolerance=station.rg2.grip_tolerance,
        grip_force=station.rg2.grip_force,
        plan_ahead=run.plan_ahead,
        indication_timeout=run.indication_timeout,
        indication_give_up=run.indication_give_up,
        recover_tries=run.recover_tries,
        path_timeout=run.path_timeout,
        anticipate=scenario.interaction_model().anticipates,
        guard=GuardSettings(
            threshold=run.place_guard,
            descent=options.approach_distance,
            enabled=run.place_guard > 0,
        ),
        gripper_time=options.gripper_time,
    )


# Bounds for skipping the forecast monitor far from the body (ours, generous for a UR3 and
# the parts it carries): a point of the robot lies within REACH_BOUND of some body origin of
# its envelope, moves at most TCP_BOUND, and stops within STOP_BOUND.
REACH_BOUND, TCP_BOUND, STOP_BOUND = 0.25, 1.0, 0.5  # m, m/s, s
# Forecast samples whose body the forecast monitor keeps: more than a re-timing's horizon
# holds (the plan's rest, `safety.max_wait` and 1 s, at `OperatorForecast.SAMPLE`).
BODIES_KEPT = 256


def forecast_monitor(
    pipeline: SeparationPipeline, safety: SafetyConfig, acceleration: float, period: float
) -> ScaleFn:
    """The forecast monitor of predictive separation (`ScaleFn`): the controller's monitor's
    planned limit for a pose of the plan at full speed beside one forecast sample, on the
    controller's `pipeline`, with the arm's joint `acceleration` limit [rad/s²] and the
    monitor's `period` [s]."""
    lag = MONITOR_LAG * period
    reach = REACH_BOUND + max(
        (NEAR_SPEED + TCP_BOUND) * (safety.reaction_time + period + STOP_BOUND), 0.0
    )

    # Each forecast sample is asked about at many poses: its body, by its values, is kept.
    bodies: dict[tuple, BodySpheres] = {}

    def body_of(centres, radii, velocities) -> BodySpheres:
        values = (np.asarray(a, dtype=float).tobytes() for a in (centres, radii, velocities))
        key = (len(radii), *values)
        found = bodies.get(key)
        if found is None:
            if len(bodies) >= BODIES_KEPT:
                bodies.pop(next(iter(bodies)))  # the oldest
            found = bodies[key] = forecast_body(centres, radii, velocities)
        return found

    def scale(q, qdot, opening, carrying, centres, radii, velocities) -> float:
        spheres = body_of(centres, radii, velocities)
        if len(spheres.radii) == 0:
            return 1.0
        # Far from every sphere the monitor cannot limit: skip its full assessment.
        robot = pipeline.robot(q, opening, carrying)
        near = spheres.centres[None, :, :] - robot.p_WB[:, None, :]
        if (np.linalg.norm(near, axis=2) - spheres.radii[None]).min() > (
            reach + safety.slow_band + safety.human_uncertainty
        ):
            return 1.0
        # The monitor's planned limit (`assess`) of the plan at full speed: its velocities now
        # and ahead are `qdot`, so only the plan's row is needed.
        qdot = np.asarray(qdot, dtype=float)
        geometry = pipeline.pairs(q, opening, carrying, spheres)
        v_r1 = np.maximum(0.0, geometry.robot_speeds(qdot[None, :])[0])
        t_s1 = stopping_time(np.abs(qdot), acceleration)
        return planned_limit(geometry, v_r1, t_s1, safety, period, lag)

    return scale


def keep_clear_settings(
    scenario: Scenario,
    design: CellDesign,
    envelope: RobotEnvelope | SeparationPipeline | None,
    options: MotionOptions,
) -> KeepClearSettings:
    """Predictive separation's forecast and forecast monitor for `scenario`: with
    `safety.separation: predictive` and an operator on a shared desk (`body.activity: desk`);
    otherwise none (reactive: the monitor alone). The forecast assumes the scenario's person,
    not the one each operator seed draws: the controller does not know who stands there.
    `envelope`: the controller's model of the robot, or its `SeparationPipeline` (shared with
    its monitor)."""
    safety, body = planning_settings(scenario.safety), scenario.body
    predictive = safety.separation == Separation.PREDICTIVE
    if not predictive or envelope is None or body.activity != Activity.DESK:
        return KeepClearSettings(max_wait=safety.max_wait, departure=safety.departure)
    pipeline = pipeline_of(envelope)
    desk = desk_of(load_cell_frames(design), design.layout)
    delay = scenario.interaction_model().delay
    forecast = OperatorForecast(
        body.person(), desk, delay.median, delay.sigma, safety.forecast_spread
    )
    acceleration = options.joint_acceleration_limit
    scale = forecast_monitor(pipeline, safety, acceleration, scenario.run.period)
    return KeepClearSettings(
        forecast,
        remembered(scale),
        safety.max_wait,
        safety.departure,
        safety.timing,
        acceleration,
        safety.reaction_time,
        # With separation alone the monitor keeps S_p without the waits; a wait that leaves the
        # motion slowed all the same only lengthened the assembly (time_around's docstring).
        clear_only=safety.contact_speed <= 0.0,
    )


def body_age(scenario: Scenario) -> BodyAge:
    """What the separation monitor allows for the body reading's age under the scenario's
    `sensors:`: its tracker's staleness bound (an exact tracker: none)."""
    model = sensor_models(scenario.sensors).get(PORTS["body"])
    return BodyAge() if model is None else BodyAge(stale_after=model.stale_after)


def make_controller(
    scenario: Scenario,
    design: CellDesign,
    space: StateSpace,
    policy: Policy,
    plans: PlanService,
    home: np.ndarray,
    options: MotionOptions,
    on_task: Callable[[TaskRecord], None] | None = None,
) -> Controller:
    """The controller of `scenario`'s cell: the Supervisor (proposals from `policy`, plans from
    `plans`, from and to `home`) and, with an operator body, the separation monitor, both
    reading the tracked body through `BodyMemory`. `on_task(record)` hears every task."""
    builder = DiagramBuilder()
    limits = supervisor_limits(scenario, options)
    opening = scenario.station.rg2.initial_opening
    # One pipeline for the controller's side: its monitor and its forecast monitor.
    pipeline = (
        SeparationPipeline(RobotEnvelope(design), FORECAST_POSES_KEPT)
        if scenario.body.enabled
        else None
    )
    clear = keep_clear_settings(scenario, design, pipeline, options)
    envelope = pipeline.envelope if pipeline is not None else RobotEnvelope(design)
    within = PlanLimits(envelope, scenario.safety.limits)
    supervisor = builder.AddNamedSystem(
        "supervisor",
        Supervisor(space, policy, plans, home, opening, limits, on_task, clear, within),
    )
    for name in (*MEASURED, *LINK_READINGS):
        if name != "operator.body":
            builder.ExportInput(supervisor.GetInputPort(name), name)
    for name in (*ARM_PORTS, "hri.prompt", "status"):
        builder.ExportOutput(supervisor.GetOutputPort(name), name)
    monitor = None
    if scenario.body.enabled:
        monitor = _add_monitor(builder, scenario, design, options, pipeline, supervisor)
    diagram = builder.Build()
    diagram.set_name("cell_controller")
    return Controller(diagram, supervisor, monitor)


def _add_monitor(builder, scenario: Scenario, design, options, pipeline, supervisor):
    """The separation monitor (returned) and the body memory before it and the Supervisor, on
    the controller's `pipeline`; the monitor's speed limit into the Supervisor."""
    monitor = builder.AddNamedSystem(
        "separation_monitor",
        ControllerSeparationMonitor(
            design,
            planning_settings(scenario.safety),
            options.joint_acceleration_limit,
            scenario.run.period,
            pipeline,
            body_age(scenario),
        ),
    )
    builder.ConnectInput("ur3.state_estimated", monitor.GetInputPort("ur3.state_estimated"))
    builder.ConnectInput("rg2.state_measured", monitor.GetInputPort("rg2.state_measured"))
    memory = builder.AddNamedSystem(
        "body_memory", BodyMemory(scenario.run.period, planning_settings(scenario.safety))
    )
    builder.ExportInput(memory.GetInputPort("tracked"), "operator.body")
    body = memory.GetOutputPort("operator.body")
    builder.Connect(body, monitor.GetInputPort("operator.body"))
    builder.Connect(body, supervisor.GetInputPort("operator.body"))
    builder.Connect(supervisor.GetOutputPort("intent"), monitor.GetInputPort("intent"))
    builder.Connect(monitor.GetOutputPort("speed_limit"), supervisor.GetInputPort("speed_limit"))
    return monitor


def connect_controller(builder: DiagramBuilder, station, controller) -> None:
    """Wire a station and a controller (both added to `builder`) by their port names: the
    station's measured outputs into the controller, its commands back (a controller without a
    separation monitor leaves the tracked body unread; the `LINK_READINGS` a station has no
    port for are left unconnected)."""
    for name in MEASURED:
        if controller.HasInputPort(name):
            builder.Connect(station.GetOutputPort(name), controller.GetInputPort(name))
    for name in LINK_READINGS:
        if station.HasOutputPort(name) and controller.HasInputPort(name):
            builder.Connect(station.GetOutputPort(name), controller.GetInputPort(name))
    for name in COMMANDED:
        builder.Connect(controller.GetOutputPort(name), station.GetInputPort(name))


__all__ = [
    "COMMANDED",
    "LINK_READINGS",
    "MEASURED",
    "PENDANT",
    "WATCHDOG",
    "Controller",
    "connect_controller",
    "make_controller",
]
