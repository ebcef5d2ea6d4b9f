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
    token, the square on 2-3 a little slower, undo 8 s; every placement carries its part from
    2.5 s to 4 s, a re-target costs 0.8 s at most and a swap 4 s (about the planned figures)."""
    from hrc_drake.tasks.costs import table_from_seconds, task_edges, uniform_bets
    from hrc_drake.tasks.tokens import UNDO

    seconds = {}
    for state, task in task_edges(flange_space):
        if task == UNDO:
            seconds[state, task] = 8.0
        else:
            seconds[state, task] = 10.0 + 0.2 * flange_space.tokens.index(task)
            if task == "S23":
                seconds[state, task] += 0.3
    bets = uniform_bets(flange_space, retarget=0.8, swap=4.0)
    return table_from_seconds(flange_space, seconds, carry=TOY_CARRY, bets=bets)


TOY_CARRY = (2.5, 4.0)  # the toy table's carry milestones [s from a placement's start]
