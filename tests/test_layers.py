"""The layers keep to their side: the task layer and the Drake-free tools import no pydrake, and
the motion layer knows no Q-learning (each checked in a fresh interpreter)."""

from __future__ import annotations

import subprocess
import sys

DRAKE_FREE = [
    "hrc_drake.tasks.spec",
    "hrc_drake.tasks.graph",
    "hrc_drake.tasks.mdp",
    "hrc_drake.tasks.learn",
    "hrc_drake.tasks.solve",
    "hrc_drake.tasks.deciders",
    "hrc_drake.tasks.operator_model",
    "hrc_drake.tasks.interaction",
    "hrc_drake.tasks.profile",
    "hrc_drake.scenario.schema",
    "hrc_drake.scenario.safety",
    "hrc_drake.scenario.drivers",
    "hrc_drake.drivers.settings",
    "hrc_drake.scenario.check",
    "hrc_drake.scenario.load",
    "hrc_drake.hri.populations",
    "hrc_drake.hri.messages",
    "hrc_drake.motion.options",
    "hrc_drake.evaluate",
    "hrc_drake.cli.evaluate",
    "hrc_drake.gym",
    "hrc_drake.cli",
]
LEARNING = ["hrc_drake.tasks.mdp", "hrc_drake.tasks.learn", "hrc_drake.tasks.deciders"]
CONTROLLER = ["hrc_drake.cell.controller"]


def _loaded_after_import(modules: list[str], watched: list[str]) -> list[str]:
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module(m)\n"
        f"print(','.join(w for w in {watched!r} if w in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    return [w for w in out.stdout.strip().split(",") if w]


def test_task_layer_and_tools_import_no_drake():
    assert _loaded_after_import(DRAKE_FREE, ["pydrake"]) == []


def test_motion_layer_knows_no_q_learning():
    """Every module of the motion layer (new ones included)."""
    import pkgutil

    import hrc_drake.motion as motion

    modules = [f"hrc_drake.motion.{m.name}" for m in pkgutil.iter_modules(motion.__path__)]
    assert len(modules) > 10
    assert _loaded_after_import(modules, [*LEARNING, "pydrake"]) == ["pydrake"]


def test_the_controller_loads_nothing_of_the_simulated_station():
    """Importing the controller room (in a fresh interpreter) loads no module of the station
    room: the import graph says so of the source (tests/test_import_cycles.py), this of what
    Python actually loads, package `__init__`s included."""
    import pkgutil

    import hrc_drake.cell.station as station

    watched = [f"hrc_drake.cell.station.{m.name}" for m in pkgutil.iter_modules(station.__path__)]
    assert len(watched) > 5
    assert _loaded_after_import(CONTROLLER, ["hrc_drake.cell.station", *watched]) == []
