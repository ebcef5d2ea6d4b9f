import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.mdp import build_mdp
from hrc_drake.tasks.spec import load_spec


@pytest.fixture(scope="session")
def flange_space():
    return generate_states(load_spec())


@pytest.fixture(scope="session")
def flange_mdp(flange_space):
    return build_mdp(flange_space)


@pytest.fixture(scope="session")
def toy_costs(flange_space):
    """A hand-made cost table of the flange case (no motion planning): placements 10-11.4 s by
    token, the square on 2-3 a little slower, undo 8 s."""
    from hrc_drake.tasks.costs import table_from_seconds, task_edges
    from hrc_drake.tasks.tokens import UNDO

    seconds = {}
    for state, task in task_edges(flange_space):
        if task == UNDO:
            seconds[state, task] = 8.0
        else:
            seconds[state, task] = 10.0 + 0.2 * flange_space.tokens.index(task)
            if task == "S23":
                seconds[state, task] += 0.3
    return table_from_seconds(flange_space, seconds)
