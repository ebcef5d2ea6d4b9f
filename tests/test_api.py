"""The package namespace is the library's first page (`docs/api.md`): every name in
`hrc_drake.__all__` resolves, `import hrc_drake` stays cheap and Drake-free, and a script using
only those names runs a scenario from outside the checkout."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hrc_drake

REPO = Path(__file__).resolve().parents[1]


def _fresh(code: str, cwd: Path | None = None, timeout: float = 120) -> str:
    """stdout of `code` run by this interpreter in a fresh process (stderr in the failure)."""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, timeout=timeout
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_every_exported_name_resolves():
    assert len(hrc_drake.__all__) == len(set(hrc_drake.__all__))
    # `__all__` is the `_EXPORTS` table's names, and each names a real object.
    assert set(hrc_drake.__all__) == {"__version__", *hrc_drake._EXPORTS}
    for name in hrc_drake.__all__:
        assert getattr(hrc_drake, name) is not None, name
    assert set(hrc_drake.__all__) <= set(dir(hrc_drake))
    assert hrc_drake.EvaluationSetup.__name__ == "Setup"  # hrc_drake.evaluation_runs.Setup
    assert callable(hrc_drake.evaluate_decider) and callable(hrc_drake.run_scenario)
    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        hrc_drake.no_such_name  # noqa: B018


def test_the_version_is_the_distributions():
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert hrc_drake.__version__ == project["version"]


def test_import_loads_nothing_heavy_and_the_task_layer_no_drake():
    """`import hrc_drake` imports no numpy or Drake (names load on first use); the task layer
    and the Drake-free exports, reached through it, load no Drake (`tests/test_layers.py`)."""
    watched = ["pydrake", "numpy", "hrc_drake.tasks"]
    code = (
        "import sys, hrc_drake\n"
        f"print(','.join(m for m in {watched!r} if m in sys.modules))\n"
        "import hrc_drake.tasks, hrc_drake.tasks.learn\n"
        "from hrc_drake import load_spec, generate_states, exact_policy, train, load_scenario\n"
        "from hrc_drake import evaluate_decider, EvaluationSetup, load_cost_table\n"
        "print('pydrake' in sys.modules)\n"
    )
    before, tasks = _fresh(code).splitlines()
    assert before == ""
    assert tasks == "False"


def test_the_task_layer_through_the_exports():
    """Solve and learn a policy with the exported names only: on the flange case the learned
    policy's choice is an optimal one in every state (ties, such as F1 or F3 first, may differ
    from the exact policy's)."""
    space = hrc_drake.generate_states(hrc_drake.load_spec())
    mdp = hrc_drake.build_mdp(space, hrc_drake.MdpConfig())
    solution = hrc_drake.solve_exact(mdp)
    assert isinstance(solution, hrc_drake.Solution)
    exact = hrc_drake.exact_policy(space)
    result = hrc_drake.train(mdp, seed=0)
    assert isinstance(result, hrc_drake.LearningResult) and result.converged
    learned = hrc_drake.policy_from_choices(mdp, result.choice, "q-learning")
    assert isinstance(learned, hrc_drake.Policy)
    assert learned.table.keys() == exact.table.keys()
    chosen = result.choice >= 0
    assert np.array_equal(chosen, solution.choice >= 0)
    best = solution.values[chosen]
    assert np.allclose(solution.q[result.choice[chosen]], best, rtol=0, atol=1e-9)


SCRIPT = """\
import hrc_drake

scenario = hrc_drake.load_scenario("row1-optimal", hrc_drake.LEAN)
result = hrc_drake.run_scenario(scenario)
for state in result.states:
    print("state:", " ".join(state) or "(empty)")
print("final:", result.final_kind, "done:", result.done)
print("collisions:", len(result.collisions))
"""


@pytest.mark.slow
def test_a_script_of_exported_names_runs_a_scenario_outside_the_checkout(tmp_path):
    """The leanest catalogue run (row 1, the operator follows; 0.5 s holds), from a script in a
    temporary folder: the installed package finds its models and scenarios by itself."""
    script = tmp_path / "run_row1.py"
    script.write_text(SCRIPT)
    python = REPO / ".venv" / "bin" / "python"
    if not python.exists():
        python = Path(sys.executable)
    done = subprocess.run(
        [str(python), str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stdout.splitlines()
    states = [line.removeprefix("state: ") for line in lines if line.startswith("state: ")]
    # Row 1 of Table 2: the operator follows the minimum-effort sequence.
    assert states == ["(empty)", "F1", "F1 S23", "F1 S23 F03"], done.stdout
    assert "final: terminal done: True" in lines
    assert "collisions: 0" in lines
