"""Monte Carlo runs through the physical cell: the cell side of `hrc-drake evaluate --cell`.

A cell run is one closed-loop simulation (`hrc_drake.cell.run.run.run_scenario`) of a base scenario
(default `row1-optimal`, with the evaluated assembly) in which the decider proposes at every task
boundary (`DeciderPolicy`), the population's operator model answers, and the decider learns from
each task as the cell observed it (from contact, not from the answer). Every run builds its own
diagram and its own motion planner: no run uses plans that another run cached, so runs are
independent and the same seeds give the same report however the runs are spread over processes
or machines (Drake diagrams do not pickle, so each worker builds its own anyway).

What a cell run reports, beside the task-level figures: its time is the cell's simulated time
(motion, bolting holds, the parts settling, and what the interaction adds: the indication's
delay where the robot waits for it, a re-target or a swap where its bet was wrong); the
boundaries where the robot started on the decider's bet, re-targeted and swapped, as the
Supervisor recorded them; the robot's idle time at each boundary, in simulated seconds and in
wall-clock seconds (`wall_idle`: how long it waited for the planner after the answer, near 0 when
the task was planned ahead while the operator bolted), and whether that plan was ready is
recorded per boundary.

Every run is a scenario: the base scenario with one YAML text over it (`CellOptions.run_text`:
the evaluation's overrides, the interaction, the run's operator with its seeds and the decider),
exactly what `hrc-drake simulate --scenario BASE --scenario-text TEXT` loads, so a run that failed
replays alone with the same result (`CellOptions.replay`).

`CellOptions` is what `hrc_drake.evaluation_runs.Setup.cell` holds: the task-level evaluation
calls its methods and never imports this module; this module imports it (one way).
"""

from __future__ import annotations

import dataclasses
import math
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hrc_drake.evaluate import predicted_tasks, simulate_run
from hrc_drake.evaluation_runs import RunResult, run_seed
from hrc_drake.paths import UsageError
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.interaction import MODES, InteractionCosts, operator_delays
from hrc_drake.tasks.policy import PolicyFileError
from hrc_drake.tasks.protocols import TiresAlongTheRun, TotalDelay
from hrc_drake.tasks.tokens import UNDO
from hrc_drake.typed_yaml import dump_flow, load_tagged

DEFAULT_BASE_SCENARIO = "row1-optimal"


class DeciderPolicy:
    """A decider as the Supervisor's policy: proposals from the decider, predictions of the
    operator's answer (for planning ahead) from its operator model, if it has one."""

    def __init__(self, decider, space: StateSpace):
        self.decider = decider
        self.space = space

    def next_task(self, state: tuple[str, ...]) -> str | None:
        """The decider's proposal in `state`; None in a terminal state."""
        if self.space.kind[self.space.index(state)] == StateKind.TERMINAL:
            return None
        return self.decider.propose(tuple(state))

    def predicted_tasks(self, state: tuple[str, ...]) -> list[str]:
        """The tasks to plan ahead for `state`, most likely first
        (`hrc_drake.evaluate.predicted_tasks`)."""
        proposal = self.next_task(state)
        return [] if proposal is None else predicted_tasks(self.decider, state, proposal)

    def commit(self, state: tuple[str, ...], proposal: str) -> str | None:
        """The placement the decider bets on before the indication (None: it waits)."""
        return self.decider.commit(tuple(state), proposal)

    def observe(self, record) -> None:
        """The Supervisor's `on_task`: the decider learns what the cell observed."""
        self.decider.observe(record.state, record.proposed, record.observed)

    def matches(self, spec: AssemblySpec) -> None:
        """PolicyFileError unless the decider was made for `spec`."""
        if spec.spec_hash != self.space.spec.spec_hash:
            raise PolicyFileError(
                f"the decider was made for assembly {self.space.spec.name!r}, not {spec.name!r}"
            )


@dataclass(frozen=True)
class CellOptions:
    """Which cell runs an evaluation: a base scenario, YAML overrides and the interaction mode
    the cell plays (None: the scenario's) (picklable); the `hrc_drake.evaluation_runs.CellRuns` of
    `Setup.cell`."""

    scenario: str = DEFAULT_BASE_SCENARIO
    overrides: tuple[str, ...] = ()
    mode: str | None = None
    costs: str = ""
    """The cost table file the deciders were made with (`--costs`); empty: the cell's own,
    cached (`default_cost_table`). Replays name it."""

    def __post_init__(self):
        if self.mode is not None and self.mode not in MODES:
            raise UsageError(f"interaction mode {self.mode!r}: use one of {', '.join(MODES)}")

    def prepare(self, space: StateSpace):
        """The scenario every run plays (`evaluation_scenario`)."""
        return evaluation_scenario(self, space.spec)

    def check(self, operator, model_name: str) -> None:
        """UsageError for an operator model the cell cannot play (`check_cell_operator`)."""
        check_cell_operator(operator, model_name)

    def play(self, scenario, setup, decider, run: int) -> RunResult:
        """Run `run` of the evaluation `setup` (`hrc_drake.evaluation_runs.Setup`) through the cell:
        the scenario of `run_text`, its operator as the scenario builds it, and `decider`
        (reset by the caller) proposing (`play_cell_run`)."""
        scenario = self.run_scenario(setup, run)
        operator = scenario.operator_for(setup.space)
        return play_cell_run(scenario, setup.space, decider, operator)

    def _lean(self) -> bool:
        from hrc_drake.cell.scenario import LEAN

        return bool(self.overrides) and self.overrides[0] == LEAN

    def run_text(self, setup, run: int) -> str:
        """The one YAML text over the base scenario that makes it run `run` of the evaluation
        `setup`: the overrides (but `--lean`'s, a flag of its own), the evaluated assembly when
        it is not the base's, the interaction the deciders price (mode, interface and delay:
        the simulated operator draws from it and the forecast reads it), the run's operator (the
        population's model and parameters, seeded `run_seed(seed, run)`, its delays drawn from
        `delay_generator(seed, run)`, whatever the base's operator was) and the decider."""
        from hrc_drake.scenario.load import load_scenario

        data: dict[str, Any] = {}
        for text in self.overrides[1:] if self._lean() else self.overrides:
            _merge(data, _numbers(load_tagged(text) or {}))  # tags (`!GripLost`) kept
        spec = setup.space.spec
        base = load_scenario(self.scenario)
        source = Path(spec.source) if spec.source else None
        own = source is None or not source.is_file()  # as `evaluation_scenario` decides
        if not own and source.resolve() != base.assembly_path.resolve():
            data["assembly"] = str(source.resolve())
        it = setup.interaction
        delay = {"distribution": it.delay.distribution, "median": it.delay.median}
        delay["sigma"] = it.delay.sigma
        params = {k: _param(v) for k, v in setup.params.items()}
        costs = {"costs": self.costs} if self.costs else {}  # left out: the cell's, cached
        operator = {
            # Scripted deviations or a stochastic operator of the base would clash with the
            # model (and are not what the evaluation played).
            "deviations": [],
            "override_prob": 0.0,
            "mistake_prob": 0.0,
            "model": setup.operator_model,
            "params": params,
            "seed": run_seed(setup.seed, run),
            "delay_seed": [setup.seed, run],
        }
        _merge(
            data,
            {
                "interaction": {"mode": it.mode, "interface": it.interface, "delay": delay},
                "operator": operator,
                "decider": {"name": setup.decider, "seed": setup.seed, **costs},
            },
        )
        return dump_flow(data)

    def run_scenario(self, setup, run: int):
        """The scenario of run `run`: the base with `--lean`'s text, then `run_text`, loaded as
        `simulate` loads it."""
        from hrc_drake.cell.scenario import LEAN, load_cell_scenario

        texts = [LEAN] if self._lean() else []
        return load_cell_scenario(self.scenario, [*texts, self.run_text(setup, run)])

    def replay(self, setup, run: int) -> str | None:
        """The `hrc-drake simulate` command that plays run `run` of `setup` alone, shell-quoted;
        None when no run plays alone: a decider that keeps its model across runs (after the
        first), or one started from an operator profile."""
        if setup.model is not None or (setup.keep_model and run > 0):
            return None
        base = self.scenario
        if Path(base).suffix:  # a file: from anywhere
            base = str(Path(base).resolve())
        lean = ["--lean"] if self._lean() else []
        args = ["hrc-drake", "simulate", "--scenario", base, *lean]
        return shlex.join([*args, "--scenario-text", self.run_text(setup, run)])

    def playing(self, mode: str) -> CellOptions:
        """These options with the cell playing the interaction `mode`."""
        return dataclasses.replace(self, mode=mode)

    def describe(self, space: StateSpace) -> dict[str, Any]:
        """What ran: the base scenario's settings with the evaluated assembly (when it is not
        the base's own) and the population's operator, and the overrides applied on top."""
        from hrc_drake.scenario.load import load_scenario

        spec = space.spec
        base = load_scenario(self.scenario)
        same = bool(spec.source) and Path(spec.source).resolve() == base.assembly_path.resolve()
        what = "its operator" if same else f"assembly {spec.name} ({spec.source}) and an operator"
        return {
            "scenario": f"{self.scenario} with {what} from the population model",
            "base_scenario": self.scenario,
            "scenario_overrides": list(self.overrides),
            "separation": load_scenario(self.scenario, list(self.overrides)).safety.separation,
        }


def _merge(into: dict, data: dict) -> dict:
    """`data` merged into `into` key by key (nested mappings merge, anything else replaces), as
    the scenario loader applies one override after another."""
    for key, value in data.items():
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = value
    return into


# A number PyYAML reads as text for want of a dot (5e-3); the scenario loaders read a number.
_EXPONENT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")


def _numbers(data):
    """`data` with every text that the scenario loaders read as a number made a number, so that
    written out again it is not quoted (Drake's loader refuses a quoted number)."""
    if isinstance(data, dict):
        return {k: _numbers(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_numbers(v) for v in data]
    if isinstance(data, str) and _EXPONENT.match(data.strip()):
        return float(data)
    return data


def _param(value):
    """An operator model parameter as a scenario holds it: a number, else its text (`--param`
    gives text: `p=0.3`, `order=S23`)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)


def decider_policy(scenario, space: StateSpace, progress=None) -> DeciderPolicy:
    """The scenario's `decider` as the Supervisor's policy, made as `evaluate` makes it: its
    name and seed, the cost table (`decider.costs`, else the cell's, cached; `progress` sees it
    planned the first time) and the scenario's interaction."""
    from hrc_drake.tasks.costs import load_cost_table
    from hrc_drake.tasks.deciders import make_decider

    config = scenario.decider
    if config.costs:
        costs = load_cost_table(config.costs, space)
    else:
        from hrc_drake.cell.run.costs import default_cost_table

        costs = default_cost_table(space, progress=progress)
    costs = costs.with_handover_time(scenario.run.handover_time)  # as its operator takes it
    interaction = scenario.interaction_model()
    decider = make_decider(config.name, space, costs, config.seed, interaction)
    return DeciderPolicy(decider, space)


def evaluation_scenario(options: CellOptions, spec: AssemblySpec):
    """The base scenario with the overrides, for the assembly `spec` (its source file), playing
    the options' interaction mode."""
    from hrc_drake.cell.scenario import load_cell_scenario

    scenario = load_cell_scenario(options.scenario, list(options.overrides))
    if spec.source and Path(spec.source).is_file():
        scenario = dataclasses.replace(scenario, assembly=str(spec.source))
    if options.mode is None:
        return scenario
    interaction = dataclasses.replace(scenario.interaction, mode=options.mode)
    return dataclasses.replace(scenario, interaction=interaction)


class _PolicyDecider:
    """A scenario's policy as a task-level decider: it proposes, learns nothing and bets on
    its proposal (as the Supervisor does with a policy that has no `commit`)."""

    def __init__(self, policy):
        self.policy = policy

    def propose(self, state: tuple[str, ...]) -> str:
        return self.policy.next_task(state)

    def observe(self, state, proposal, observed) -> None:
        pass


def task_level_run(scenario, space: StateSpace, costs) -> RunResult:
    """The scenario's run played at task level from the cost table `costs`: its policy
    proposes (and, anticipating, starts on its proposal), its operator answers after the delays
    the simulated station waits (the same seeded draws, step by step), and each task takes
    the table's seconds plus what the interaction adds (`hrc_drake.evaluate.simulate_run`).
    What the cell's run of the scenario should take, if the task level mirrors the cell."""
    from hrc_drake.cell.run.run import scenario_policy

    operator = scenario.operator_for(space)
    timeline = InteractionCosts(space, costs, scenario.interaction_model())
    decider = _PolicyDecider(scenario_policy(scenario, space))
    delays = operator_delays(scenario.operator.seed)
    return simulate_run(space, costs, decider, operator, timeline, delays)


def check_cell_operator(operator, model_name: str) -> None:
    """UsageError for an operator model the cell cannot play: one whose bolting scale
    (`bolt_scale(step)`, which the simulated operator's bolting time is multiplied by: `slow`
    tires along the run) is not a positive finite factor."""
    if not isinstance(operator, TiresAlongTheRun):
        return
    scale = operator.bolt_scale
    for step in (1, 2, 5, 30):
        factor = float(scale(step))
        if not (math.isfinite(factor) and factor > 0.0):
            raise UsageError(
                f"operator model {model_name!r}: bolt_scale({step}) is {factor}; the cell "
                "multiplies the operator's bolting time by it, so it must be a positive number"
            )


def play_cell_run(scenario, space: StateSpace, decider, operator):
    """One run of `decider` against `operator` through the cell; the decider is not reset.
    Returns an `hrc_drake.evaluation_runs.RunResult` with the cell's idle times and interaction (the
    delays the operator drew, when it draws them: `DelayedIndications`)."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import cell_design, motion_options
    from hrc_drake.motion.planner import MotionPlanner

    policy = DeciderPolicy(decider, space)
    planner = MotionPlanner(motion_options(scenario), design=cell_design(scenario, space.spec))
    result = run_scenario(
        scenario,
        policy,
        operator=operator,
        on_task=policy.observe,
        motion_planner=planner,
        space=space,
    )
    if result.interrupted:
        # Ctrl-C in the middle of a run: the evaluation reports the runs done, not this one.
        raise KeyboardInterrupt
    tasks, check = result.tasks, result.safety_check
    return RunResult(
        completed=bool(result.done),
        seconds=float(result.sim_time),
        tasks=len(tasks),
        undos=sum(t.observed == UNDO for t in tasks),
        deviations=sum(t.indicated != t.proposed for t in tasks),
        idle=tuple(float(x) for x in result.idle[: len(tasks)]),
        wall_idle=tuple(float(x) for x in result.wall_idle[: len(tasks)]),
        plan_ready=tuple(bool(x) for x in result.plan_ready[: len(tasks)]),
        error=result.error,
        collisions=len(result.collisions),
        commits=sum(t.committed is not None for t in tasks),
        retargets=sum(bool(t.retargeted) for t in tasks),
        swaps=sum(bool(t.swapped) for t in tasks),
        indication_delay=float(operator.total_delay() if isinstance(operator, TotalDelay) else 0.0),
        states=tuple(result.names),
        violations=0 if check is None else int(check.violations),
        unsafe=0 if check is None else int(check.beyond_permissible + check.contacts_beyond),
        handovers=result.handovers,
        capped=result.capped,
    )
