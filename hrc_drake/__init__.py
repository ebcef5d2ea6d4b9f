"""Task-and-motion stack on Drake for human-robot collaborative assembly.

The names a script needs (`docs/api.md`): load an assembly spec and its states, solve or learn a
policy, load a scenario and run it in the cell, evaluate deciders against operator populations.

    import hrc_drake

    scenario = hrc_drake.load_scenario("row1-optimal", hrc_drake.LEAN)
    result = hrc_drake.run_scenario(scenario)
    print(result.states, result.done)

Each name is imported when first used (module `__getattr__`), so `import hrc_drake` loads
neither Drake nor numpy, and the task layer (`hrc_drake.tasks`) stays Drake-free when imported
through this package (`tests/test_api.py`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # for type checkers and editors; at run time `__getattr__` imports
    from hrc_drake.cell.run.costs import default_cost_table
    from hrc_drake.cell.run.result import RunResult
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN
    from hrc_drake.evaluate import evaluate as evaluate_decider
    from hrc_drake.evaluation_runs import Setup as EvaluationSetup
    from hrc_drake.scenario.load import load_scenario
    from hrc_drake.scenario.schema import Scenario
    from hrc_drake.tasks.assembly import AssemblySpec
    from hrc_drake.tasks.costs import CostTable, load_cost_table
    from hrc_drake.tasks.graph import StateSpace, generate_states
    from hrc_drake.tasks.learn import LearningResult, train
    from hrc_drake.tasks.mdp import MdpConfig, build_mdp
    from hrc_drake.tasks.policy import Policy, load_policy, policy_from_choices, save_policy
    from hrc_drake.tasks.solve import Solution, exact_policy, solve_exact
    from hrc_drake.tasks.spec import load_spec

# Exported name -> (module, name there). Only `run_scenario`, `LEAN`, `RunResult` and
# `default_cost_table` load Drake; the rest are the Drake-free task layer and scenario loader.
_EXPORTS = {
    # an assembly and its states
    "load_spec": ("hrc_drake.tasks.spec", "load_spec"),
    "AssemblySpec": ("hrc_drake.tasks.assembly", "AssemblySpec"),
    "generate_states": ("hrc_drake.tasks.graph", "generate_states"),
    "StateSpace": ("hrc_drake.tasks.graph", "StateSpace"),
    # policies: exact and learned
    "MdpConfig": ("hrc_drake.tasks.mdp", "MdpConfig"),
    "build_mdp": ("hrc_drake.tasks.mdp", "build_mdp"),
    "exact_policy": ("hrc_drake.tasks.solve", "exact_policy"),
    "solve_exact": ("hrc_drake.tasks.solve", "solve_exact"),
    "Solution": ("hrc_drake.tasks.solve", "Solution"),
    "train": ("hrc_drake.tasks.learn", "train"),
    "LearningResult": ("hrc_drake.tasks.learn", "LearningResult"),
    "policy_from_choices": ("hrc_drake.tasks.policy", "policy_from_choices"),
    "Policy": ("hrc_drake.tasks.policy", "Policy"),
    "save_policy": ("hrc_drake.tasks.policy", "save_policy"),
    "load_policy": ("hrc_drake.tasks.policy", "load_policy"),
    # scenarios and the cell
    "load_scenario": ("hrc_drake.scenario.load", "load_scenario"),
    "Scenario": ("hrc_drake.scenario.schema", "Scenario"),
    "LEAN": ("hrc_drake.cell.scenario", "LEAN"),
    "run_scenario": ("hrc_drake.cell.run.run", "run_scenario"),
    "RunResult": ("hrc_drake.cell.run.result", "RunResult"),
    # evaluation (not `evaluate`: that name is the submodule `hrc_drake.evaluate`, which
    # rebinds it when imported)
    "evaluate_decider": ("hrc_drake.evaluate", "evaluate"),
    "EvaluationSetup": ("hrc_drake.evaluation_runs", "Setup"),
    "CostTable": ("hrc_drake.tasks.costs", "CostTable"),
    "load_cost_table": ("hrc_drake.tasks.costs", "load_cost_table"),
    "default_cost_table": ("hrc_drake.cell.run.costs", "default_cost_table"),
}

__all__ = [
    "LEAN",
    "AssemblySpec",
    "CostTable",
    "EvaluationSetup",
    "LearningResult",
    "MdpConfig",
    "Policy",
    "RunResult",
    "Scenario",
    "Solution",
    "StateSpace",
    "__version__",
    "build_mdp",
    "default_cost_table",
    "evaluate_decider",
    "exact_policy",
    "generate_states",
    "load_cost_table",
    "load_policy",
    "load_scenario",
    "load_spec",
    "policy_from_choices",
    "run_scenario",
    "save_policy",
    "solve_exact",
    "train",
]


def _version() -> str:
    """The installed distribution's version; from a checkout that is not installed, the one
    `pyproject.toml` states."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hrc_drake")
    except PackageNotFoundError:
        import tomllib
        from pathlib import Path

        pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
        try:
            return tomllib.loads(pyproject.read_text())["project"]["version"]
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "unknown"


def __getattr__(name: str):
    """Import an exported name on first use, then keep it in the package's namespace (the
    version too: `importlib.metadata` alone costs more than the rest of `import hrc_drake`)."""
    if name == "__version__":
        value = _version()
    elif name in _EXPORTS:
        module, attribute = _EXPORTS[name]
        value = getattr(importlib.import_module(module), attribute)
    else:
        raise AttributeError(f"module 'hrc_drake' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The exported names too, before their first use (for completion in editors)."""
    return sorted({*globals(), *__all__})
