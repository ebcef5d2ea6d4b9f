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
