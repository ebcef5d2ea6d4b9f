"""The Gymnasium environment: check_env, masks, P in the Taxi form, the operator as randomness."""

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from hrc_drake.gym import ENV_ID, AssemblyEnv  # noqa: E402
from hrc_drake.tasks.mdp import MdpConfig, build_mdp  # noqa: E402
from hrc_drake.tasks.solve import solve_exact  # noqa: E402
from hrc_drake.tasks.tokens import UNDO  # noqa: E402


@pytest.fixture
def env(flange_space):
    return AssemblyEnv(space=flange_space)


def test_check_env_passes(flange_space):
    env = AssemblyEnv(space=flange_space, config=MdpConfig(override_prob=0.2))
    check_env(env, skip_render_check=True)
    check_env(gymnasium.make(ENV_ID, render_mode="ansi").unwrapped)  # with a spec: render too


def test_spaces_and_action_mask(env, flange_space):
    assert env.observation_space.n == flange_space.n_states == 20
    assert env.tasks == (*flange_space.tokens, UNDO)
    obs, info = env.reset(seed=0)
    assert obs == 0
    mask = info["action_mask"]
    assert mask.dtype == np.int8
    assert [env.tasks[a] for a in np.flatnonzero(mask)] == ["F1", "F2", "F3", "S12", "S23"]
    s7 = flange_space.index(("F1", "S23"))
    assert [env.tasks[a] for a in np.flatnonzero(env.action_mask(s7))] == ["F02", "F03", UNDO]


def test_infeasible_action_is_a_penalised_no_op(env):
    env.reset(seed=0)
    undo = len(env.tasks) - 1
    obs, reward, terminated, truncated, info = env.step(undo)  # nothing to undo at the start
    assert (obs, reward, terminated, truncated, info["infeasible"]) == (0, -1.0, False, False, True)
    with pytest.raises(ValueError, match="outside Discrete"):
        env.step(len(env.tasks))


def test_an_optimal_run_ends_terminated_with_the_papers_rewards(env):
    env.reset(seed=0)
    total, terminated = 0.0, False
    for task in ("S12", "F01", "F3"):
        obs, reward, terminated, truncated, info = env.step(env.tasks.index(task))
        total += reward
        assert info["task"] == task and not truncated
    assert terminated and env.space.name(obs) == "17"
    assert total == -1 - 1 + 2
    assert not env.action_mask(obs).any()


def test_transitions_in_the_taxi_form_match_the_exact_solver(flange_space):
    config = MdpConfig(override_prob=0.1, mistake_prob=0.05)
    env = AssemblyEnv(space=flange_space, config=config)
    for s in env.P:
        for outcomes in env.P[s].values():
            assert sum(p for p, _, _, _ in outcomes) == pytest.approx(1.0)
            for p, nxt, _, terminated in outcomes:
                assert 0 < p <= 1 and isinstance(terminated, bool)
                assert terminated == (env.space.name(nxt) in {"10", "11", "17", "20"})
    s7 = flange_space.index(("F1", "S23"))
    f03 = {env.space.name(n): p for p, n, _, _ in env.P[s7][env.tasks.index("F03")]}
    # Proposed F03: performed with 0.9, else F02 or undo (0.05 each); a placement on the square
    # lands in its row with 0.95, in the other with 0.05.
    expected = {"10": 0.9 * 0.95 + 0.05 * 0.05, "9": 0.9 * 0.05 + 0.05 * 0.95, "2": 0.05}
    assert f03 == pytest.approx(expected)
    # Value iteration over P (feasible actions only) gives the exact solver's values.
    gamma = config.gamma
    values = np.zeros(env.observation_space.n)
    for _ in range(500):
        new = values.copy()
        for s in env.P:
            feasible = np.flatnonzero(env.action_mask(s))
            if len(feasible):
                new[s] = max(
                    sum(p * (r + (0.0 if t else gamma * values[n])) for p, n, r, t in env.P[s][a])
                    for a in feasible
                )
        values = new
    exact = solve_exact(build_mdp(flange_space, config)).values
    assert values == pytest.approx(exact, abs=1e-8)


def test_the_operator_is_the_randomness(flange_space):
    """Mistakes on the square: about 5 % of F03 from state 7 end in state 9; seeded."""
    env = AssemblyEnv(space=flange_space)
    s7 = flange_space.index(("F1", "S23"))
    f03 = env.tasks.index("F03")
    env.reset(seed=7)
    outcomes = []
    for _ in range(2000):
        env.reset(options={"state": s7})
        outcomes.append(env.space.name(env.step(f03)[0]))
    assert 0.03 < outcomes.count("9") / len(outcomes) < 0.07
    env.reset(seed=7)
    again = []
    for _ in range(2000):
        env.reset(options={"state": ("F1", "S23")})
        again.append(env.space.name(env.step(f03)[0]))
    assert again == outcomes


def test_a_custom_operator_overrides_the_proposal(flange_space):
    def always_square_first(state, proposed, feasible, rng):
        return next((t for t in feasible if t.startswith("S")), proposed)

    env = AssemblyEnv(
        space=flange_space, config=MdpConfig(mistake_prob=0.0), operator=always_square_first
    )
    env.reset(seed=0)
    obs, _, _, _, info = env.step(env.tasks.index("F1"))
    assert (info["proposed"], info["task"], env.space.sequence(obs)) == ("F1", "S12", ("S12",))

    env = AssemblyEnv(space=flange_space, operator=lambda *args: "F9")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="operator performed 'F9'"):
        env.step(0)


def test_episodes_are_truncated(flange_space):
    env = AssemblyEnv(space=flange_space, max_steps=3)
    env.reset(seed=0)
    undo = len(env.tasks) - 1
    results = [env.step(undo)[3] for _ in range(3)]
    assert results == [False, False, True]


def test_time_costs_give_seconds_as_rewards(flange_space):
    from test_costs import _table

    env = AssemblyEnv(space=flange_space, costs=_table(flange_space))
    env.reset(seed=0)
    _, reward, _, _, _ = env.step(env.tasks.index("F1"))
    assert reward == pytest.approx(-10.96)
    assert env.config.gamma == 1.0


def test_ansi_render(flange_space):
    env = AssemblyEnv(space=flange_space, render_mode="ansi")
    env.reset(seed=0)
    env.step(env.tasks.index("F1"))
    text = env.render()
    assert text.startswith("state 2: F1 [normal] after proposing F1; feasible: S23, undo")


def test_make_by_module_id_in_a_fresh_process():
    """Gymnasium 1.x loads no plugin entry points: a fresh interpreter makes the environment
    from the module-qualified id, which imports hrc_drake.gym (and so registers it) itself."""
    import subprocess
    import sys

    code = (
        "import sys, gymnasium\n"
        "assert 'hrc_drake.gym' not in sys.modules\n"
        "env = gymnasium.make('hrc_drake.gym:hrc_drake/Assembly-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(env.spec.id, obs, int(info['action_mask'].sum()))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    ).stdout
    assert out.split() == [ENV_ID, "0", "5"]
