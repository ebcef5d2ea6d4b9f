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
    "hrc_drake.hri.scenario",
    "hrc_drake.hri.populations",
    "hrc_drake.hri.messages",
    "hrc_drake.motion.options",
    "hrc_drake.evaluate",
    "hrc_drake.cli.evaluate",
    "hrc_drake.gym",
    "hrc_drake.cli",
]
MOTION = [
    "hrc_drake.motion.planner",
    "hrc_drake.motion.validate",
    "hrc_drake.motion.poses",
    "hrc_drake.motion.scene",
    "hrc_drake.motion.plan_io",
    "hrc_drake.motion.service",
]
LEARNING = ["hrc_drake.tasks.mdp", "hrc_drake.tasks.learn", "hrc_drake.tasks.deciders"]


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
    assert _loaded_after_import(MOTION, [*LEARNING, "pydrake"]) == ["pydrake"]
