"""What an evaluation's runs are made of: the setup every worker plays runs from (`Setup`; at
cell level its `CellRuns`), the operator's seed of each run (`run_seed`) and what a run gives
(`RunResult`).

These values pass between the run loop and its workers (`hrc_drake.evaluate`), the report
(`hrc_drake.evaluation_report`) and the cell's runs (`hrc_drake.cell.run.evaluate`); they are
apart so that each of those reads them without importing the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from hrc_drake.tasks.costs import CostTable
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.interaction import Interaction
from hrc_drake.tasks.operator_model import OnlineOperatorModel


@dataclass(frozen=True)
class RunResult:
    """One run: whether it finished, its simulated seconds, tasks, undos and deviations, the
    robot's idle seconds and whether the plan was ready, per boundary; at cell level also the
    run's error and its robot collisions. The interaction: boundaries where the robot started on
    its prediction (`commits`), re-targeted and swapped; the indication delays drawn
    (`indication_delay`, summed) and the seconds the robot stood waiting for an indication
    (`indication_wait`: the whole delay when it waited, the rest of it when a right bet reached
    the seat first)."""

    completed: bool
    seconds: float
    tasks: int
    undos: int
    deviations: int
    idle: tuple[float, ...] = ()
    plan_ready: tuple[bool, ...] = ()
    error: str | None = None
    collisions: int = 0
    commits: int = 0
    retargets: int = 0
    swaps: int = 0
    indication_delay: float = 0.0
    indication_wait: float = 0.0
    wall_idle: tuple[float, ...] = ()  # cell level: the idle waits in wall-clock seconds
    states: tuple[str, ...] = ()
    """Cell only: the states the run went through (their names)."""
    violations: int = 0
    """Cell only: steps inside S_p by the run's own check (`hrc_drake.cell.run.safety_check`; 0
    without the operator's body): power and force limiting may permit them."""
    unsafe: int = 0
    """Cell only: what the run's check finds beyond ISO/TS 15066: steps inside S_p faster than
    the body region permits, and contacts beyond its permissible force (a failure)."""
    handovers: int = 0
    """Cell only: tasks the robot handed over and the operator did by hand."""
    capped: bool = False
    """Ended by the run's own task cap (not terminal, no failure: an operator who keeps undoing
    can outlast any cap)."""


def run_seed(seed: int, run: int) -> int:
    """The operator's seed of run `run` of an evaluation seeded `seed`."""
    return int(np.random.SeedSequence([seed, run]).generate_state(1)[0])


class CellRuns(Protocol):
    """What plays runs through the physical cell (picklable: it travels to every worker)."""

    def prepare(self, space: StateSpace) -> Any:
        """What every run of a worker shares (the scenario); errors here are the user's input."""

    def check(self, operator, model_name: str) -> None:
        """UsageError for an operator model the cell cannot play."""

    def play(self, prepared: Any, setup: Setup, decider, run: int) -> RunResult:
        """Run `run` of the evaluation `setup`; the decider is not reset."""

    def replay(self, setup: Setup, run: int) -> str | None:
        """The command that plays run `run` alone (None: it cannot be played alone)."""

    def playing(self, mode: str) -> CellRuns:
        """The same cell playing the interaction `mode` (`anticipate`, `wait`)."""

    def describe(self, space: StateSpace) -> dict[str, Any]:
        """The report's keys naming what ran (the scenario, its overrides)."""


@dataclass(frozen=True)
class Setup:
    """What every worker needs to play runs (picklable)."""

    space: StateSpace
    costs: CostTable
    decider: str
    operator_model: str
    params: dict[str, Any]
    seed: int
    interaction: Interaction = field(default_factory=Interaction)
    keep_model: bool = False
    """One operator, many assemblies: the decider keeps its operator model across the runs
    (`start_run` instead of `reset`), so the runs follow each other in one process."""
    model: OnlineOperatorModel | None = None
    """An operator profile's model for `mpc` to start from (None: a fresh one)."""
    cell: CellRuns | None = None
    """None: task level; else runs through the cell (`hrc_drake.cell.run.evaluate.CellOptions`)."""
