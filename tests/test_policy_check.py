"""The policy check (`hrc-drake check-policy`, `hrc_drake.tasks.policy_check`), the refusal of a
policy that never finishes by the commands that run one, and the streamed listings of `states`
and `policy`."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from hrc_drake.cli import main
from hrc_drake.tasks import listing
from hrc_drake.tasks.decide import StepLimitError, minimum_effort_violations, run_decisions
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.mdp import MdpConfig
from hrc_drake.tasks.policy import PolicyFileError, load_policy, next_states, save_policy
from hrc_drake.tasks.policy_check import check_policy, load_runnable_policy
from hrc_drake.tasks.solve import exact_policy, tasks_to_finish
from hrc_drake.tasks.spec import load_spec

# Two host flanges on five slots (414 states): `train --schedule explore --seed 2` gives a
# greedy policy that loops from 3 states, in a fraction of a second.
SPEC = Path(__file__).parent / "data" / "two-host-five.yaml"
EXPLORE_SEED = 2


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def space():
    return generate_states(load_spec(SPEC))


@pytest.fixture(scope="module")
def explore_file(tmp_path_factory):
    """The policy file a user gets from `hrc-drake train --schedule explore` on SPEC."""
    path = tmp_path_factory.mktemp("explore") / "q.json"
    argv = ["train", "--assembly", SPEC, "--schedule", "explore", "--seed", EXPLORE_SEED]
    assert main([str(a) for a in [*argv, "--out", path]]) == 0
    return path


def test_the_check_finds_where_explore_loops_as_the_decision_loop_plays_it(space, explore_file):
    policy = load_policy(explore_file, space)
    check = check_policy(space, policy)
    loops = check.non_terminal & check.walks.loops
    assert loops.sum() > 0, "explore's policy on this spec loops (the case the check is for)"
    # Every non-terminal state, played by the decision loop from there (no deviation): it
    # loops exactly where the check says, and elsewhere takes the check's number of tasks.
    for s in np.flatnonzero(check.non_terminal).tolist():
        start = space.sequence(s)
        if loops[s]:
            with pytest.raises(StepLimitError, match="the policy loops"):
                run_decisions(space, policy, start=start, max_steps=60)
        else:
            states, _ = run_decisions(space, policy, start=start, max_steps=60)
            assert len(states) - 1 == check.walks.steps[s], start
    # Minimum effort by the number of tasks: the looping states, and only those here.
    violations = minimum_effort_violations(space, policy)
    assert set(violations) == {space.sequence(s) for s in np.flatnonzero(check.not_minimum)}
    assert {space.sequence(s) for s in np.flatnonzero(loops)} <= set(violations)
    assert all("loops" in violations[space.sequence(s)] for s in np.flatnonzero(loops))
    # The value gap: none where the policy takes the fewest tasks from the start, positive
    # where it loops, infinite there without discount.
    gap = check.gap
    assert gap[0] == 0 and np.all(gap[loops] > 1.0)
    undiscounted = check_policy(space, policy, MdpConfig(gamma=1.0)).gap
    assert np.all(np.isinf(undiscounted[loops]))


def test_the_check_finds_where_explore_loops_on_a_larger_spec():
    """Four oval flanges and two hosts on seven slots (11,426 states): today's `explore` stops
    at its sweep cap with a policy that loops from about 150 states. The check finds every
    one (the decision loop, played from each, hits the loop); the default schedule (`cover`)
    leaves none."""
    from hrc_drake.tasks.learn import CoverageSchedule, ExploringStartsSchedule, train
    from hrc_drake.tasks.mdp import build_mdp
    from hrc_drake.tasks.policy import policy_from_choices

    big = generate_states(load_spec(SPEC.parent / "two-host-seven.yaml"))
    mdp = build_mdp(big)
    explore = policy_from_choices(mdp, train(mdp, ExploringStartsSchedule()).choice, "explore")
    check = check_policy(big, explore, values=False)
    loops = np.flatnonzero(check.non_terminal & check.walks.loops)
    assert len(loops) > 50
    for s in loops.tolist():
        with pytest.raises(StepLimitError, match="the policy loops"):
            run_decisions(big, explore, start=big.sequence(s), max_steps=40)
    finishing = np.flatnonzero(check.non_terminal & ~check.walks.loops)
    for s in np.random.default_rng(0).choice(finishing, 300, replace=False).tolist():
        states, _ = run_decisions(big, explore, start=big.sequence(s), max_steps=40)
        assert len(states) - 1 == check.walks.steps[s]
    cover = policy_from_choices(mdp, train(mdp, CoverageSchedule()).choice, "cover")
    summary = check_policy(big, cover, values=False).summary()
    assert summary["loops"] == summary["not_minimum_effort"] == 0


def test_the_exact_policy_passes_the_check(space):
    check = check_policy(space, exact_policy(space))
    summary = check.summary()
    assert summary["not_minimum_effort"] == summary["loops"] == summary["missing"] == 0
    assert summary["minimum_effort"] == summary["non_terminal"] == int(check.non_terminal.sum())
    assert summary["value_gap"]["max"] == 0 and summary["value_gap"]["max_at"] is None
    np.testing.assert_array_equal(
        check.walks.steps[check.non_terminal], check.fewest[check.non_terminal]
    )


def test_check_policy_command_lists_the_loops_and_exits_1(capsys, space, explore_file):
    code, out, _ = run(capsys, "check-policy", "--assembly", SPEC, "--policy", explore_file)
    check = check_policy(space, load_policy(explore_file, space), values=False)
    first = " ".join(space.sequence(int(np.flatnonzero(check.not_minimum)[0])))
    assert code == 1
    assert f"of which {int(check.walks.loops[check.non_terminal].sum())} loop" in out
    assert f"  {first}" in out and "loops, fewest" in out
    code, out, _ = run(
        capsys, "check-policy", "--assembly", SPEC, "--policy", explore_file, "--json"
    )
    report = json.loads(out)
    assert code == 1 and report["loops"] == int((check.non_terminal & check.walks.loops).sum())
    looping = [r for r in report["not_minimum_effort_states"] if r["loops"]]
    assert len(looping) == report["loops"] and all(r["tasks"] is None for r in looping)
    assert report["value_gap"]["max"] > 1.0 and report["value_gap"]["gamma"] == 0.95


def test_the_commands_that_run_a_policy_refuse_one_that_loops(
    capsys, monkeypatch, space, explore_file
):
    check = check_policy(space, load_policy(explore_file, space), values=False)
    bad = np.flatnonzero(check.unfinished)
    words = [
        f"from {len(bad)} states never reaches a terminal state",
        str(list(space.sequence(int(bad[0])))),
        f"`hrc-drake check-policy --policy {explore_file} --assembly {SPEC}` lists them",
    ]
    code, _, err = run(capsys, "react", "--assembly", SPEC, "--policy", explore_file)
    _one_line_error(code, err, "react", *words)
    # simulate: refused with the arguments, before any station, controller or planner is
    # built; the same whether the policy comes from --policy or from the scenario.
    import hrc_drake.cli.simulate as simulate

    def no_run(*_args, **_kwargs):
        raise AssertionError("a refused policy must not reach a run")

    monkeypatch.setattr(simulate, "run_scenario", no_run)
    for given in (["--policy", explore_file], ["--scenario-text", f"{{policy: {explore_file}}}"]):
        code, _, err = run(capsys, "simulate", "--assembly", SPEC, "--lean", *given)
        _one_line_error(code, err, "simulate", *words)
    # `policy` shows the policy it is given (it runs nothing).
    code, out, _ = run(capsys, "policy", "--assembly", SPEC, "--policy", explore_file)
    assert code == 0 and len(out.splitlines()) == space.n_states


def _one_line_error(code, err, command, *words):
    assert code == 2, err
    assert err.startswith(f"hrc-drake {command}: error: ") and err.count("\n") == 1, err
    for word in words:
        assert word in err, (word, err)


def test_a_policy_with_a_state_missing_is_refused_where_it_would_be_reached(tmp_path, space):
    policy = exact_policy(space)
    table = dict(policy.table)
    gone = space.sequence(int(next_states(space, policy)[0]))  # the start's proposal
    del table[gone]
    path = tmp_path / "holed.json"
    save_policy(dataclasses.replace(policy, table=table), path)
    check = check_policy(space, load_policy(path, space))
    assert check.missing.sum() == 1 and check.unfinished[0] and not check.walks.loops[0]
    assert check.summary()["start_tasks"] is None
    with pytest.raises(PolicyFileError, match="gives no feasible task on the way"):
        load_runnable_policy(path, space)


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ((("F1", "F9"), "undo"), r"names \['F1', 'F9'\], not a state of 'two-host-five'"),
        (((), "undo"), r"gives task 'undo' in \[\], where it is not feasible"),
        ((("F1",), "F1"), r"gives task 'F1' in \['F1'\], where it is not feasible"),
    ],
)
def test_a_policy_file_with_an_impossible_entry_is_refused(tmp_path, space, entry, message):
    policy = exact_policy(space)
    table = {**policy.table, entry[0]: entry[1]}
    path = tmp_path / "bad.json"
    save_policy(dataclasses.replace(policy, table=table), path)
    with pytest.raises(PolicyFileError, match=message):
        load_policy(path, space)


def test_many_sequences_map_to_their_states_at_once(space):
    sequences = [space.sequence(s) for s in range(space.n_states)]
    np.testing.assert_array_equal(space.indices(sequences), np.arange(space.n_states))
    first = sequences[1]
    strange = [(*first, "undo"), ("F9",), (*first, *first), (first[0], 3)]
    np.testing.assert_array_equal(space.indices(strange), -1)
    paths = space.token_paths(np.arange(space.n_states))
    assert [tuple(space.tokens[t] for t in row if t >= 0) for row in paths] == sequences


def _old_state_rows(space):
    """The rows `hrc-drake states --json` printed before it streamed them (the reference)."""
    best = tasks_to_finish(space)
    rows = [
        {
            "name": space.name(s),
            "sequence": list(space.sequence(s)),
            "configuration": sorted(space.configuration(s)),
            "kind": space.state_kind(s).key,
            "tasks": [t for t, _ in space.tasks(s)],
            "actions": sorted({space.action_label(t) for t, _ in space.tasks(s)}),
            "tasks_to_finish": int(best[s]),
        }
        for s in range(space.n_states)
    ]
    if all(r["name"].isdigit() for r in rows):
        rows.sort(key=lambda r: int(r["name"]))
    return rows


def _old_policy_rows(space, policy):
    rows = []
    for s in range(space.n_states):
        seq = space.sequence(s)
        task = policy.next_task(seq)
        after = None if task is None else list(space.sequence(dict(space.tasks(s))[task]))
        rows.append(
            {"sequence": list(seq), "kind": space.state_kind(s).key, "task": task, "next": after}
        )
    return rows


@pytest.mark.parametrize("assembly", [None, SPEC], ids=["flange", "two-host-five"])
def test_streamed_listings_are_the_json_they_were(capsys, monkeypatch, tmp_path, assembly):
    """Byte for byte what `json.dump(rows, indent=1)` wrote, rows in small chunks (the flange
    case with its Table 1 names and order; a spec without names), for the exact policy and
    for a policy file with an undo in it."""
    monkeypatch.setattr(listing, "CHUNK", 7)
    space = generate_states(load_spec(assembly))
    flag = [] if assembly is None else ["--assembly", assembly]
    _, out, _ = run(capsys, "states", "--json", *flag)
    assert out == json.dumps(_old_state_rows(space), indent=1) + "\n"
    exact = exact_policy(space)
    _, out, _ = run(capsys, "policy", "--json", *flag)
    assert out == json.dumps(_old_policy_rows(space, exact), indent=1) + "\n"
    edited = dataclasses.replace(exact, table={**exact.table, space.sequence(1): "undo"})
    save_policy(edited, tmp_path / "p.json")
    _, out, _ = run(capsys, "policy", "--json", *flag, "--policy", tmp_path / "p.json")
    assert out == json.dumps(_old_policy_rows(space, edited), indent=1) + "\n"
    assert json.loads(out)[1]["task"] == "undo" and json.loads(out)[1]["next"] == []
