"""Learning against an adversary: minimax-Q's worst case equals the exact min-max's from every
(state, mistakes left); the exact solve agrees with an exhaustive game-tree search."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest

from hrc_drake.cli import main
from hrc_drake.tasks.adversary import (
    NEVER,
    MinimaxSchedule,
    adversary_game,
    agreement,
    paper_return,
    policy_worst_case,
    solve_minimax,
    train_minimax,
)
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import load_policy
from hrc_drake.tasks.solve import solve_exact, tasks_to_finish
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

REPO = Path(__file__).resolve().parents[1]
FOUR_SLOT = REPO / "models" / "assemblies" / "four-slot.yaml"


@functools.cache
def _space(spec: str):
    return generate_states(load_spec(None if spec == "flange" else FOUR_SLOT))


@functools.cache
def _solved(spec: str, budget: int):
    game = adversary_game(_space(spec), budget)
    return game, solve_minimax(game)


def _search_worst_case(space, budget: int) -> dict[tuple[int, int], int]:
    """Worst-case tasks to finish from every non-terminal (state, mistakes left) by exhaustive
    AND-OR search on the task sequences (not the MDP's arrays): can the robot force a terminal
    state within `b` tasks, for b = 1, 2, ..? The operator follows, or misplaces (another seat
    of the proposal's part and mount, for a pair named in the spec's `mistakes`) while it has
    mistakes left; an undo is only followed."""
    table, mounts = space.table, list(space.spec.mounts)
    prone = {i for i, m in enumerate(mounts) if (m.part, m.on) in set(space.spec.mistakes)}
    mount = {tok: int(table.mount[i]) for i, tok in enumerate(space.tokens)}

    def answers(s: int, task: str, k: int) -> list[tuple[int, int]]:
        tasks = dict(space.tasks(s))
        out = [(tasks[task], k)]
        if task != UNDO and k > 0 and mount[task] in prone:
            out += [
                (dst, k - 1)
                for t, dst in tasks.items()
                if t not in (task, UNDO) and mount[t] == mount[task]
            ]
        return out

    @functools.cache
    def can_finish(s: int, k: int, b: int) -> bool:
        if space.state_kind(s) == StateKind.TERMINAL:
            return True
        return b > 0 and any(
            all(can_finish(s2, k2, b - 1) for s2, k2 in answers(s, task, k))
            for task, _ in space.tasks(s)
        )

    worst = {}
    for s in range(space.n_states):
        if space.state_kind(s) != StateKind.TERMINAL:
            for k in range(budget + 1):
                worst[s, k] = next(b for b in range(1, 100) if can_finish(s, k, b))
    return worst


@pytest.mark.parametrize("spec", ["flange", "four-slot"])
@pytest.mark.parametrize("budget", [1, 2])
def test_exact_minimax_agrees_with_exhaustive_search(spec, budget):
    game, exact = _solved(spec, budget)
    searched = _search_worst_case(game.space, budget)
    assert {(s, k): int(exact.tasks[k, s]) for s, k in searched} == searched
    # No mistake left: the fewest tasks; the game value is the paper's return of the tasks.
    assert np.array_equal(exact.tasks[0], tasks_to_finish(game.space))
    assert np.allclose(exact.values, paper_return(exact.tasks, game.gamma), atol=1e-12)
    # The min-max proposals hold the operator's best response to the min-max tasks.
    assert agreement(exact, policy_worst_case(game, exact.choice)).all_equal


@pytest.mark.parametrize("spec", ["flange", "four-slot"])
@pytest.mark.parametrize("budget", [1, 2])
def test_learner_worst_case_equals_exact_minimax_from_every_state(spec, budget):
    game, exact = _solved(spec, budget)
    result = train_minimax(game, seed=budget)
    assert result.converged
    worst = policy_worst_case(game, result.choice)  # the operator's exact best response
    live = ~game.terminal()
    assert np.array_equal(worst[:, live], exact.tasks[:, live])
    assert np.allclose(result.values, exact.values, atol=1e-12)


def test_learner_sees_every_answer_and_only_those():
    """Coverage: the answers the learner stored for each (mistakes left, proposal) are the
    game's, though it never reads them (a follower only with no mistake left)."""
    game, _ = _solved("four-slot", 2)
    result = train_minimax(game, seed=0)
    mdp = game.mdp
    for k in range(3):
        for e in range(mdp.n_edges):
            outs = range(int(mdp.out_start[e]), int(mdp.out_start[e + 1]))
            legal = {int(game.performed[o]) for o in outs if k > 0 or not game.deviates[o]}
            stored = {int(a) for a in result.answer[k, e] if a >= 0}
            assert stored == legal, (k, mdp.task_name(e))


def test_learner_guards_where_the_minimum_effort_policy_does_not():
    """With 2 mistakes to come on the 4-slot spec, the expected-value minimum-effort policy (the
    `exact` decider's, 5 % mistakes) can be made to take longer than min-max from some states:
    there the learner proposes something else and its worst case is the min-max one."""
    game, exact = _solved("four-slot", 2)
    space = game.space
    effort = solve_exact(build_mdp(space, MdpConfig())).choice
    effort_worst = policy_worst_case(game, effort)
    live = ~game.terminal()
    longer = np.argwhere((effort_worst > exact.tasks) & live)
    assert len(longer) > 0
    result = train_minimax(game, seed=0)
    learned = policy_worst_case(game, result.choice)
    for k, s in longer:
        assert learned[k, s] == exact.tasks[k, s] < effort_worst[k, s]
    # Where both undo, the difference is further on; somewhere the proposal itself differs.
    assert any(result.choice[k, s] != effort[s] for k, s in longer)
    # One of them, spelled out: an oval flange on slot 2, two mistakes to come. The square on
    # 3-4 leaves a flange to seat on it that may be misplaced twice (6 tasks); the undo does not.
    s = space.index(("F2",))
    assert effort_worst[2, s] == 6 and exact.tasks[2, s] == 4
    assert game.mdp.task_name(int(result.choice[2, s])) == UNDO


def test_best_response_finds_a_policy_that_loops():
    """A policy that proposes F1 on the empty base and undoes it never finishes: -1."""
    game, exact = _solved("flange", 1)
    space, mdp = game.space, game.mdp
    choice = exact.choice[1].copy()
    for seq, task in (((), "F1"), (("F1",), UNDO)):
        s = space.index(seq)
        choice[s] = next(e for e in mdp.edges_of(s) if mdp.task_name(e) == task)
    worst = policy_worst_case(game, choice)
    assert worst[0, 0] == worst[1, 0] == NEVER
    assert agreement(exact, worst).loops >= 4  # the two states, at both levels


def test_stop_rule_and_seed():
    """Cut short, the learner says it has not settled and is off somewhere; the same seed gives
    the same table."""
    game, exact = _solved("four-slot", 2)
    short = train_minimax(game, MinimaxSchedule(max_rounds=1), seed=0)
    assert not short.converged and short.rounds == 1
    assert not agreement(exact, policy_worst_case(game, short.choice)).all_equal
    a, b = train_minimax(game, seed=4), train_minimax(game, seed=4)
    assert np.array_equal(a.q, b.q, equal_nan=True) and a.episodes == b.episodes


def test_adversary_command(tmp_path, capsys):
    out = tmp_path / "minimax.json"
    args = ["adversary", "--assembly", str(FOUR_SLOT), "--mistakes", "2", "--json"]
    assert main([*args, "--out", str(out)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["converged"] and report["equal"] == report["augmented_states"] == 84
    assert report["minimum_effort"]["longer"] > 0
    policy = load_policy(out, _space("four-slot"))
    assert policy.method == "minimax-q" and policy.meta["mistakes"] == 2
    assert policy.next_task(("F2",)) == UNDO
    with pytest.raises(SystemExit) as refused:
        main(["adversary", "--mistakes", "-1"])
    assert refused.value.code == 2
    assert "--mistakes" in capsys.readouterr().err
    with pytest.raises(SystemExit) as refused:
        main(["adversary", "--mistake-prob", "1"])
    assert refused.value.code == 2
    assert "--mistake-prob" in capsys.readouterr().err
