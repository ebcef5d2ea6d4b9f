"""Runs with the station in another process, over LCM (`hrc_drake.cell.link.interface`).

`hrc-drake station --scenario S --lcm URL` serves the simulated station of S (`serve_scenario`);
`hrc-drake simulate --scenario S --station-lcm URL` runs the controller of S against it
(`run_over_lcm`). Both sides build what a one-process run (`hrc_drake.cell.run.run`) builds from
the same scenario (the station with the arm at the motion planner's home; the controller with
its policy and planner), and the lockstep keeps the order of its events: the two-process run
has the same states, terminal and collisions as the one-process run, and, from the station's
session report (`hrc_drake.cell.link.station_record`), the same `faults` and `safety.function`.
Before the first step the two compare the scenarios they were started with
(`hrc_drake.cell.link.scenario_identity`) and refuse, on both sides, a pair that differs
(`ScenarioMismatch`).

With a `pace` (`--realtime`) both sides run in real time instead (`hrc_drake.cell.link.realtime`):
each simulator paced to the wall clock, each channel at its device's rate, the newest reading
taken; the run then has the scenario's states and terminal, not the one-process run's timing,
and its result reports how the controller kept its pace (`RunResult.realtime`).
"""

from __future__ import annotations

from pydrake.lcm import DrakeLcm
from pydrake.systems.framework import Diagram

from hrc_drake.cell.link.interface import end_station_session, make_cell_station_interface
from hrc_drake.cell.link.lockstep import (
    LockstepTimeouts,
    StationLinkError,
    check_lcm_url,
    exchange_period,
)
from hrc_drake.cell.link.realtime import RealtimeFigures, channel_rates
from hrc_drake.cell.link.realtime_client import RealtimeSession, make_realtime_station_interface
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.link.station_record import StationRecord
from hrc_drake.cell.link.station_server import serve_cell_station
from hrc_drake.cell.run.loop import ClosedLoop
from hrc_drake.cell.run.result import RunResult
from hrc_drake.cell.run.run import controller_of, prepare_run, station_of_run
from hrc_drake.cell.scenario import (
    LEAN,
    cell_design,
    load_cell_scenario,
    motion_options,
    plant_step,
)
from hrc_drake.cell.station.cell_station import CellStation
from hrc_drake.cell.station.safety_function import SafetyFunctionLog
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.spec import load_spec

# The planning worker's niceness beside a real-time controller: on a busy machine the kernel
# runs the controller's and the station's loops first (benchmarks/reports/planning_service.md).
REALTIME_PLANNER_NICE = 10


def station_of(scenario: Scenario) -> CellStation:
    """The station a run of `scenario` simulates: the arm starts at the motion planner's home,
    which a planner in this process computes as the controller's does."""
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    planner = MotionPlanner(motion_options(scenario), design=design)
    return station_of_run(prepare_run(scenario, motion_planner=planner))


def serve_scenario(
    scenario: Scenario,
    url: str,
    timeouts: LockstepTimeouts | None = None,
    identity: ScenarioIdentity | None = None,
    pace: float | None = None,
) -> dict:
    """Serve the station of `scenario` on the LCM `url` until a controller ends its session;
    the session's report (see `serve_cell_station`; with `pace`, in real time:
    `serve_realtime_station`). A controller that runs another scenario than `identity`
    (default: `scenario`'s), or runs the link otherwise, is refused with `ScenarioMismatch`."""
    if identity is None:
        identity = ScenarioIdentity.of(scenario)
    station = station_of(scenario)
    if pace is not None:
        from hrc_drake.cell.link.realtime_server import serve_realtime_station

        rates, step = channel_rates(scenario), plant_step(scenario)
        return serve_realtime_station(station, DrakeLcm(url), rates, step, pace, timeouts, identity)
    period = exchange_period(scenario)
    return serve_cell_station(station, DrakeLcm(url), period, timeouts, identity)


class RemoteCell:
    """A station served over LCM, reached through its interface, as a closed loop's cell side
    (`hrc_drake.cell.run.loop.CellSide`): no welds or stills here (the station applies its own), the
    touching pairs the station sends, and the session ended at the end of the run, whose
    report (`report`) brings the station's fault record and safety function's log. Over the
    real-time link its `session` (`RealtimeSession`) ends it and tells how the controller kept
    its pace (`realtime`)."""

    meshcat = None

    def __init__(self, interface: Diagram, session: RealtimeSession | None = None):
        self.diagram = interface
        self.report: dict | None = None  # the station's session report (after `finish`)
        self._record: StationRecord | None = None
        self._session = session

    def _context(self, root):
        return self.diagram.GetMyContextFromRoot(root)

    def touching(self, root):
        """The touching pairs by owner the station sent with its last measurements."""
        return self.diagram.GetOutputPort("sim.contacts").Eval(self._context(root))

    def welds_changed(self, root, applied: frozenset) -> bool:
        """Never: the station applies its welds itself."""
        return False

    def apply_welds(self, root) -> frozenset:
        """Nothing to apply here."""
        return frozenset()

    def injected(self, root) -> tuple:
        """The station's fault record as its session report brought it at the end of the run
        (`finish`); before that, or from a station that keeps none: none injected."""
        return () if self._record is None else self._record.injected

    def safety_function(self, root) -> SafetyFunctionLog | None:
        """The station's safety function's log as its session report brought it (None before
        `finish`, or from a station that keeps none)."""
        return None if self._record is None else self._record.safety_function

    def camera_score(self, root) -> dict | None:
        """The station camera's score as its session report brought it (None before `finish`,
        or from a station without a camera)."""
        return None if self._record is None else self._record.camera

    def configuration(self, root):
        """The configuration the station measured last."""
        return self.diagram.GetOutputPort("configuration").Eval(self._context(root))

    def save_still(self, root, path) -> None:
        """A still needs the station's camera: `simulate --station-lcm` refuses --still."""
        raise StationLinkError("a still needs the station in this process")

    def realtime(self) -> RealtimeFigures | None:
        """How the controller kept its pace over the real-time link (None: the lockstep)."""
        return None if self._session is None else self._session.figures()

    def finish(self, root) -> None:
        """End the station's session and keep its report: the run's result is read after."""
        if self._session is None:
            self.report = end_station_session(self.diagram)
        else:
            self.report = self._session.end()
        self._record = StationRecord.from_report(self.report)


def run_over_lcm(
    scenario: Scenario | str,
    url: str,
    policy: Policy | None = None,
    *,
    progress: bool = False,
    scenario_text: str | None = None,
    timeouts: LockstepTimeouts | None = None,
    on_task=None,
    identity: ScenarioIdentity | None = None,
    space: StateSpace | None = None,
    pace: float | None = None,
) -> RunResult:
    """Run the controller of `scenario` against the station served on the LCM `url` (by
    `hrc-drake station` or `serve_scenario`), as `run_scenario` runs both in one process
    (`space`: the state space of its spec, when the caller built it already); with `pace`,
    in real time at that pace (the station must serve in real time at the same pace).
    StationLinkError if the station is not there, stops answering, or fails;
    ScenarioMismatch, before the first step, if it serves another scenario than `identity`
    (default: `scenario`'s, shown with `scenario_text`) or runs the link otherwise."""
    if not isinstance(scenario, Scenario):
        scenario = load_cell_scenario(scenario, scenario_text)
    if identity is None:
        shown = [] if not scenario_text else ["--scenario-text", scenario_text]
        identity = ScenarioIdentity.of(scenario, ["--lean"] if scenario_text == LEAN else shown)
    # Paced to the wall clock, simulated time cannot stand still while the planner works (as
    # in a live run): the robot holds still meanwhile, and the planner gives way to the control
    # loops on a busy machine (its worker niced).
    realtime = pace is not None
    nice = REALTIME_PLANNER_NICE if realtime else 0
    setup = prepare_run(scenario, policy, live=realtime, space=space, nice=nice)
    lcm, link = DrakeLcm(url), None
    if pace is None:
        interface = make_cell_station_interface(
            setup.scenario, lcm, timeouts=timeouts, sim_contacts=True, identity=identity
        )
        cell = RemoteCell(interface)
    else:
        link = make_realtime_station_interface(
            setup.scenario, lcm, pace, timeouts=timeouts, sim_contacts=True, identity=identity
        )
        cell = RemoteCell(link.diagram, link.session)
    loop = ClosedLoop(setup, cell, controller_of(setup, on_task))
    if link is not None:
        link.session.greet()  # before the simulation starts: its first readings are in
    return loop.run(progress=progress, pace=pace)


__all__ = [
    "RemoteCell",
    "check_lcm_url",
    "run_over_lcm",
    "serve_scenario",
    "station_of",
]
