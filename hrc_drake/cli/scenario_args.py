"""The scenario of a command line (`hrc-drake simulate` and `hrc-drake station`): the named or
default scenario, `--lean` and `--scenario-text` layered on it (`hrc_drake.cell.scenario.
load_cell_scenario`), then what the other flags change."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from hrc_drake.cell.scenario import DEFAULT_SCENARIO, LEAN, load_cell_scenario
from hrc_drake.cli.evaluate import interaction_from_flags, separation_from_flags
from hrc_drake.scenario.load import with_operator_script
from hrc_drake.scenario.schema import OperatorConfig, Scenario


def scenario_from_args(args) -> Scenario:
    """The scenario of `simulate`'s or `station`'s options: `--scenario` (default
    `DEFAULT_SCENARIO`, or with `--assembly` an operator who follows the robot), `--lean`,
    `--scenario-text`, `--assembly`, `--operator`, `--policy`, and what `simulate` alone has
    (`--interaction`, `--interface`, `--separation`)."""
    overrides = [t for t in (LEAN if args.lean else None, *(args.scenario_text or ())) if t]
    scenario = load_cell_scenario(_scenario_name(args), overrides)
    if args.scenario_text and scenario.operator != _file_operator(args):
        # The file's description told of its own operator (a replayed evaluation run's is the
        # population's): say who will run instead.
        scenario.description = f"{describe_operator(scenario.operator)} (--scenario-text)"
    if args.assembly is not None:
        # A missing file is refused by `load_spec`, before anything is built.
        scenario = dataclasses.replace(scenario, assembly=str(args.assembly))
        if args.scenario is None:
            scenario.name = Path(args.assembly).stem
            who = describe_operator(scenario.operator).removeprefix("the ")
            scenario.description = f"assembly {args.assembly}, {who}"
    if args.operator is not None:
        scenario = with_operator_script(scenario, args.operator)
        # The file's description told of its own operator; say what will run instead.
        scenario.description = f"{describe_operator(scenario.operator)} (--operator)"
    if args.policy is not None:
        scenario = dataclasses.replace(scenario, policy=str(args.policy))
    return _with_interaction(args, scenario)


def _file_operator(args) -> OperatorConfig:
    """The operator of the scenario file (`--lean` alone over it), before `--scenario-text`."""
    lean = [LEAN] if args.lean else []
    return load_cell_scenario(_scenario_name(args), lean).operator


def describe_operator(op: OperatorConfig) -> str:
    """What the operator `op` does, in a phrase: a population model with its parameters and
    seed, a stochastic operator's probabilities, a script's steps, or following the robot."""
    if op.model:
        params = ", ".join(f"{k}={v}" for k, v in op.params.items())
        return f"a {op.model} operator ({params + ', ' if params else ''}seed {op.seed})"
    if op.override_prob > 0 or op.mistake_prob > 0:
        return (
            f"a stochastic operator (overrides with probability {op.override_prob:g}, "
            f"misplaces with {op.mistake_prob:g}, seed {op.seed})"
        )
    if op.deviations:
        steps = ", ".join(f"{d.task} at step {d.step}" for d in op.deviations)
        return (
            f"the operator performs {steps} instead of the robot's proposal, and otherwise "
            "follows the robot"
        )
    return "the operator follows the robot"


def _with_interaction(args, scenario: Scenario) -> Scenario:
    """`--interaction` and `--interface` set the scenario's interaction (a delay the scenario
    gives stays; left out, the interface's): in anticipate mode the robot starts on its
    commitment and turns if the indication names another task; in wait mode it waits for it."""
    interaction_from_flags(args)  # a bad mode or interface: one line, before anything is built
    separation = separation_from_flags(args)
    if separation is not None:
        safety = dataclasses.replace(scenario.safety, separation=separation)
        scenario = dataclasses.replace(scenario, safety=safety)
    mode, interface = getattr(args, "interaction", None), getattr(args, "interface", None)
    if mode is None and interface is None:
        return scenario
    it = scenario.interaction
    changed = dataclasses.replace(it, mode=mode or it.mode, interface=interface or it.interface)
    return dataclasses.replace(scenario, interaction=changed)


def scenario_options(args) -> list[str]:
    """The options of `args` that change what the station simulates, as arguments to give
    again (`--scenario` apart): `--assembly`, `--lean`, `--scenario-text`, `--operator`,
    `--interface`. Shown in a refused station-controller pair and in the station's hint."""
    options = []
    if args.assembly is not None:
        options += ["--assembly", str(args.assembly)]
    if args.lean:
        options.append("--lean")
    options += scenario_text_options(args)
    if args.operator is not None:
        options += ["--operator", args.operator]
    interface = getattr(args, "interface", None)
    if interface is not None:
        options += ["--interface", interface]
    return options


def scenario_text_options(args) -> list[str]:
    """`--scenario-text TEXT` for each text of `args`, in the order given."""
    return [arg for text in args.scenario_text or () for arg in ("--scenario-text", text)]


def scenario_argv(args) -> list[str]:
    """`--scenario NAME` (unless the scenario is the assembly's own, `--assembly` without
    `--scenario`) and `scenario_options(args)`: what starts the other side of a station link
    with the same scenario."""
    name = _scenario_name(args)
    return [*(["--scenario", name] if name is not None else []), *scenario_options(args)]


def _scenario_name(args) -> str | None:
    """`--scenario`, else `DEFAULT_SCENARIO` unless `--assembly` gives the assembly's own
    (None)."""
    if args.scenario is None and args.assembly is None:
        return DEFAULT_SCENARIO
    return args.scenario


__all__ = [
    "describe_operator",
    "scenario_argv",
    "scenario_from_args",
    "scenario_options",
    "scenario_text_options",
]
