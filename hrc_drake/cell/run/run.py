"""Closed-loop runs of the cell: build the station, build the controller, connect, simulate.

`run_scenario` is the runner of `hrc-drake simulate` and of `evaluate --cell`: the station comes
from the scenario (`make_cell_station`), the controller from the scenario, the policy and a
planner beside it (`make_controller`), joined in a `ClosedLoop` (`hrc_drake.cell.run.loop`), which
simulates until the Supervisor is done or stops.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams

from hrc_drake.cell.controller.build import make_controller
from hrc_drake.cell.run.loop import ClosedLoop, LocalCell, Setup
from hrc_drake.cell.run.result import RunResult
from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
from hrc_drake.cell.station.build import make_cell_station
from hrc_drake.cell.station.cell_station import CellStation
from hrc_drake.cell.station.safety_function import UNLOCK_WAIT
from hrc_drake.cell_models import CellDesign
from hrc_drake.hri.pendant import UnlockButton
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.motion.reach_check import check_reach
from hrc_drake.motion.service import (
    InlinePlanService,
    PlanService,
    planner_function,
    shared_plan_service,
)
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.decide import Operator
from hrc_drake.tasks.graph import StateSpace, generate_states
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.policy_check import load_runnable_policy
from hrc_drake.tasks.solve import exact_policy
from hrc_drake.tasks.spec import load_spec

_PLANNERS: dict[tuple, MotionPlanner] = {}


def shared_planner(options: MotionOptions, design: CellDesign | None = None) -> MotionPlanner:
    """One in-process planner (and its plan cache) per cell and set of options, shared by a
    process's scripts and tests that plan directly; checked for reach (`check_reach`)."""
    design = design if design is not None else CellDesign.of(load_spec())
    key = (options, design.key())
    if key not in _PLANNERS:
        planner = MotionPlanner(options, design=design)
        check_reach(planner)
        _PLANNERS[key] = planner
    return _PLANNERS[key]


def scenario_policy(scenario: Scenario, space) -> Policy:
    """The scenario's policy file (refused if it never finishes from some state:
    `load_runnable_policy`), or the exact minimum-effort policy."""
    if scenario.policy:
        return load_runnable_policy(scenario.policy, space)
    return exact_policy(space)


def _plan_service(
    options, design, planner, motion_planner, nice: int = 0
) -> tuple[PlanService, np.ndarray]:
    """The planner beside the controller and the home posture its plans start from: a shared
    worker process by default (at `nice`; checked for reach before anything is simulated);
    in-process when the caller hands a planner function or a MotionPlanner."""
    if motion_planner is not None:
        check_reach(motion_planner)
        function = planner if planner is not None else planner_function(motion_planner)
        return InlinePlanService(function), motion_planner.q_home
    worker = shared_plan_service(options, design, nice)
    worker.check_reach()
    if planner is not None:
        return InlinePlanService(planner), worker.q_home
    return worker, worker.q_home


def prepare_run(
    scenario: Scenario,
    policy=None,
    planner=None,
    motion_planner=None,
    live=False,
    still=None,
    space: StateSpace | None = None,
    *,
    nice: int = 0,
) -> Setup:
    """What a run of `scenario` is built from: the state space (`space`, if the caller built
    it already), the policy (the scenario's, unless given), the cell design, the planner beside
    the controller and the home posture its plans start from (the station's arm starts there),
    whether the still camera is built, and whether simulated time waits for the planner (not
    in live runs); `nice`: the planning worker's (a run paced to the wall clock lets its
    control loop go first). CellModelError if the UR3 cannot reach the spec's grasps."""
    if space is None:
        space = generate_states(load_spec(scenario.assembly_path))
    policy = policy or scenario_policy(scenario, space)
    policy.matches(space.spec)
    design = cell_design(scenario, space.spec)
    options = motion_options(scenario)
    plans, home = _plan_service(options, design, planner, motion_planner, nice)
    wait = scenario.run.wait_for_planner and not live
    return Setup(scenario, space, policy, design, options, plans, home, wait, still is not None)


def station_of_run(setup: Setup, meshcat=None, operator=None, body_script=None) -> CellStation:
    """The simulated station of a prepared run: its design and state space handed on, the arm
    starting at the planner's home."""
    return make_cell_station(
        setup.scenario,
        meshcat,
        design=setup.design,
        space=setup.space,
        arm_start=setup.home,
        camera=setup.camera,
        operator=operator,
        body_script=body_script,
    )


def controller_of(setup: Setup, on_task=None):
    """The controller of a prepared run."""
    return make_controller(
        setup.scenario,
        setup.design,
        setup.space,
        setup.policy,
        setup.plans,
        setup.home,
        setup.options,
        on_task,
    )


def build_closed_loop(
    scenario: Scenario,
    policy: Policy | None = None,
    *,
    planner=None,
    motion_planner: MotionPlanner | None = None,
    operator: Operator | None = None,
    body_script=None,
    on_task=None,
    meshcat: Meshcat | None = None,
    live: bool = False,
    on_prompt=None,
    still: tuple[float, str | Path] | None = None,
    space: StateSpace | None = None,
) -> ClosedLoop:
    """The closed loop of `scenario` in this process (the arguments are `run_scenario`'s)."""
    setup = prepare_run(scenario, policy, planner, motion_planner, live, still, space)
    bound: list[ClosedLoop] = []
    if live:
        operator = _live_operator(meshcat, setup.space, on_prompt, bound)
    station = station_of_run(setup, meshcat, operator, body_script)
    # A person in the browser also unlocks a protective stop there (non-live runs leave the
    # station's `safety.unlock` unconnected: its simulated operator unlocks).
    pendant = UnlockButton(meshcat, scenario.run.period, UNLOCK_WAIT) if live else None
    controller = controller_of(setup, on_task)
    bound.append(ClosedLoop(setup, LocalCell(station), controller, still, pendant))
    return bound[0]


def run_scenario(
    scenario: Scenario | str,
    policy: Policy | None = None,
    record: str | Path | None = None,
    progress: bool = False,
    planner=None,
    still: tuple[float, str | Path] | None = None,
    scenario_text: str | None = None,
    operator: Operator | None = None,
    body_script=None,
    live: bool = False,
    on_prompt=None,
    on_task=None,
    motion_planner: MotionPlanner | None = None,
    port: int | None = None,
    space: StateSpace | None = None,
    pace: float | None = None,
) -> RunResult:
    """Run one scenario through the station and its controller until a terminal state (or a
    stop, or Ctrl-C).

    `scenario` is a Scenario or a scenario name/path (then `scenario_text` overrides apply).
    `policy` replaces the scenario's. `planner` (a function `(configuration, task, last,
    layout) -> Plan`) replaces the motion layer's (tests use it to misplace a part);
    `motion_planner` plans in this process instead of the shared planning worker (e.g. a
    fresh one, so that a run does not use plans cached by others). `still=(t, path)` saves a
    camera image at simulated time t. `operator` (`(step, state, proposal) -> task`) replaces
    the scenario's; `body_script` the operator body's (`hrc_drake.cell.station.operator_body`).
    `live`: a person is the operator, through Meshcat buttons (`hrc_drake.hri.live`), served on
    `port`, and unlocks a protective stop there (`hrc_drake.hri.pendant`); the run paces itself
    to the wall clock (at `pace` times its speed, if given); `on_prompt` is handed to the
    `LiveOperator` (tests inject clicks from it). `on_task(record)` hears every task as the
    cell observed it. While the operator bolts, the controller plans the tasks the policy
    predicts next (its `predicted_tasks(state)` if it has one, else its `next_task(state)`).
    `space`: the state space of the scenario's spec, when the caller built it already (it is
    built once).
    CellModelError (before any simulation) if the spec does not fit the cell."""
    if not isinstance(scenario, Scenario):
        scenario = load_cell_scenario(scenario, scenario_text)
    loop = build_closed_loop(
        scenario,
        policy,
        planner=planner,
        motion_planner=motion_planner,
        operator=operator,
        body_script=body_script,
        on_task=on_task,
        meshcat=_meshcat(record is not None or live, live, port),
        live=live,
        on_prompt=on_prompt,
        still=still,
        space=space,
    )
    return loop.run(record, live, progress, pace=pace)


def _meshcat(wanted: bool, live: bool, port: int | None) -> Meshcat | None:
    """A Meshcat for a recording or a live run. Only a live run announces its address: a
    headless recording needs no browser (Drake's Meshcat always listens; its log line is
    silenced here)."""
    if not wanted:
        return None
    params = MeshcatParams()
    if port is not None:
        params.port = port
    if live:
        return Meshcat(params)
    drake_log = logging.getLogger("drake")
    level = drake_log.level
    drake_log.setLevel(logging.WARNING)
    try:
        return Meshcat(params)
    finally:
        drake_log.setLevel(level)


def _live_operator(meshcat: Meshcat, space: StateSpace, on_prompt, bound: list[ClosedLoop]):
    """A LiveOperator on the run's Meshcat, bound to the closed loop once it is built: it shows
    the proposal where the station's frames put it, at the simulator's time; after each answer
    the real-time pacing starts afresh, so that the simulation does not race to catch up the
    time the person took."""
    from hrc_drake.hri.live import LiveOperator
    from hrc_drake.motion.poses import part_pose

    def place(task, state):
        try:
            return part_pose(bound[0].station.frames, task, list(state))
        except (KeyError, ValueError, IndexError):
            return None

    def clock() -> float:
        return bound[0].simulator.get_context().get_time() if bound else 0.0

    def after_answer() -> None:
        if bound:
            bound[0].simulator.ResetStatistics()

    return LiveOperator(meshcat, space, place, clock, on_prompt, after_answer)


__all__ = [
    "ClosedLoop",
    "RunResult",
    "build_closed_loop",
    "controller_of",
    "prepare_run",
    "run_scenario",
    "scenario_policy",
    "shared_planner",
    "station_of_run",
]
