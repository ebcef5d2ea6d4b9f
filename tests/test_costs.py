"""Cost tables: file round trip, refused files, bolting times in the spec, time-aware policies."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hrc_drake.tasks.assembly import DEFAULT_BOLT_TIME, SpecError
from hrc_drake.tasks.costs import (
    CostTable,
    CostTableError,
    EdgeCost,
    load_cost_table,
    operator_seconds,
    save_cost_table,
    task_edges,
)
from hrc_drake.tasks.decide import run_decisions
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.learn import FullSchedule, train
from hrc_drake.tasks.mdp import MdpConfig, Rewards, build_mdp
from hrc_drake.tasks.policy import policy_from_choices
from hrc_drake.tasks.solve import exact_policy, timed_config
from hrc_drake.tasks.spec import parse_spec

TERMINAL = StateKind.TERMINAL

# Robot time of every task edge of the flange case [s], home to home without a bolting hold:
# benchmarks/reports/motion.md ("motion" column plus 1 s of gripper), by Table 1 state number.
ROBOT = {
    ("1", "F1"): 5.96, ("1", "F2"): 6.47, ("1", "F3"): 7.10, ("1", "S12"): 6.54,
    ("1", "S23"): 7.04, ("2", "S23"): 7.04, ("2", "undo"): 5.96, ("3", "undo"): 6.47,
    ("4", "S12"): 6.54, ("4", "undo"): 7.10, ("5", "F01"): 5.88, ("5", "F02"): 6.40,
    ("5", "undo"): 6.54, ("6", "F02"): 6.40, ("6", "F03"): 7.06, ("6", "undo"): 7.04,
    ("7", "F02"): 5.96, ("7", "F03"): 6.59, ("7", "undo"): 7.04, ("8", "F01"): 5.46,
    ("8", "F02"): 5.96, ("8", "undo"): 6.54, ("13", "F3"): 6.63, ("13", "undo"): 5.88,
    ("14", "F3"): 6.63, ("14", "undo"): 6.40, ("15", "F1"): 5.54, ("15", "undo"): 6.40,
    ("16", "F1"): 5.54, ("16", "undo"): 7.06, ("9", "undo"): 5.96, ("10", "undo"): 6.59,
    ("11", "undo"): 5.46, ("12", "undo"): 5.96, ("17", "undo"): 6.63, ("18", "undo"): 6.63,
    ("19", "undo"): 5.54, ("20", "undo"): 5.54,
}  # fmt: skip
FOUR = {
    "1 2 7 10": ("F1", "S23", "F03"),
    "1 4 8 11": ("F3", "S12", "F01"),
    "1 5 13 17": ("S12", "F01", "F3"),
    "1 6 16 20": ("S23", "F03", "F1"),
}


def _table(space, robot=ROBOT) -> CostTable:
    by_name = {space.name(s): space.sequence(s) for s in range(space.n_states)}
    entries = {}
    for (name, task), seconds in robot.items():
        state = by_name[name]
        operator = operator_seconds(space.spec, state, task)
        entries[state, task] = EdgeCost(seconds + operator, seconds, operator)
    return CostTable(space.spec.spec_hash, "test-cell", entries, space.spec.name)


def _names(space, states):
    return " ".join(space.name(space.index(s)) for s in states)


@pytest.fixture(scope="module")
def table(flange_space):
    return _table(flange_space)


def test_the_table_covers_every_edge_and_adds_its_parts(flange_space, table):
    assert len(task_edges(flange_space)) == len(ROBOT) == 38
    assert table.missing(flange_space) == []
    assert table.seconds(("F1",), "S23") == pytest.approx(7.04 + DEFAULT_BOLT_TIME)
    cost = table.cost(["F1", "S23"], "undo")
    assert cost.seconds == pytest.approx(cost.robot + cost.operator)
    # The four sequences the paper calls optimal, as in benchmarks/reports/motion.md.
    totals = {k: table.sequence_seconds(seq) for k, seq in FOUR.items()}
    assert totals == pytest.approx(
        {"1 2 7 10": 34.59, "1 4 8 11": 34.10, "1 5 13 17": 34.05, "1 6 16 20": 34.64}
    )
    with pytest.raises(KeyError, match=r"no entry for task 'F2' from state \['F1'\]"):
        table.seconds(("F1",), "F2")


def test_round_trip(tmp_path, flange_space, table):
    path = tmp_path / "costs.json"
    save_cost_table(table, path)
    data = json.loads(path.read_text())
    assert {"spec_hash", "cell_hash", "entries", "checksum"} <= set(data)
    first = data["entries"][0]
    assert set(first) == {"state", "task", "seconds", "robot", "operator"}
    loaded = load_cost_table(path, flange_space, cell_hash="test-cell")
    assert loaded.entries == table.entries
    assert (loaded.spec_hash, loaded.cell_hash) == (table.spec_hash, table.cell_hash)


def test_a_version_2_file_is_read_as_it_is(tmp_path, flange_space, toy_costs):
    """Version 2 tables (no operator's edges; undo from terminal states planned too) still load:
    the cache and the tables users made stay valid."""
    from hrc_drake.tasks.datafile import with_checksum

    path = tmp_path / "costs.json"
    save_cost_table(toy_costs, path)
    data = json.loads(path.read_text())
    data.pop("checksum")
    data["version"] = 2
    path.write_text(json.dumps(with_checksum(data)))
    loaded = load_cost_table(path, flange_space)
    assert loaded.entries == toy_costs.entries and len(loaded) == 38  # terminal undo kept, unused
    assert loaded.operator_edges() == [] and loaded.bets == toy_costs.bets


def _edit(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda p: p.write_text("{not json"), "corrupted \\(not JSON"),
        (lambda p: p.write_text(p.read_text()[:-40]), "corrupted \\(not JSON"),
        (lambda p: _edit(p, lambda d: d["entries"][0].update(seconds=1.0)), "checksum"),
        (lambda p: _edit(p, lambda d: d.update(format="x")), "not an hrc_drake cost table"),
        (lambda p: _edit(p, lambda d: d.update(version=99)), "format version 99"),
        (lambda p: p.unlink(), "not found"),
    ],
)
def test_damaged_files_are_refused(tmp_path, flange_space, table, damage, message):
    path = tmp_path / "costs.json"
    save_cost_table(table, path)
    damage(path)
    with pytest.raises(CostTableError, match=message) as err:
        load_cost_table(path, flange_space)
    assert "hrc-drake costs --out" in str(err.value)


def test_a_table_for_another_spec_or_cell_is_refused(tmp_path, flange_space, table):
    path = tmp_path / "costs.json"
    save_cost_table(table, path)
    with pytest.raises(CostTableError, match="another cell"):
        load_cost_table(path, flange_space, cell_hash="another")
    data = _spec_data()
    data["parts"]["F"]["bolt_time"] = 7.5  # the times changed: a new table is needed
    other = generate_states(parse_spec(data, "slow-bolting.yaml"))
    with pytest.raises(CostTableError, match=r"made for assembly 'flange'.*slow-bolting\.yaml"):
        load_cost_table(path, other)


def test_entries_that_are_not_edges_or_missing_are_refused(tmp_path, flange_space, table):
    path = tmp_path / "costs.json"
    entries = dict(table.entries)
    entries[("F1",), "F2"] = EdgeCost(1.0)
    save_cost_table(replace(table, entries=entries), path)
    with pytest.raises(CostTableError, match="task 'F2' in \\['F1'\\], where it is not feasible"):
        load_cost_table(path, flange_space)
    entries = {k: v for k, v in table.entries.items() if k != (("F1",), "S23")}
    save_cost_table(replace(table, entries=entries), path)
    with pytest.raises(CostTableError, match="no entry for task 'S23' from \\['F1'\\]"):
        load_cost_table(path, flange_space)


def _spec_data():
    import yaml

    from hrc_drake.resources import default_assembly

    return yaml.safe_load(default_assembly().read_text())


def test_bolt_time_in_the_spec(flange_space):
    data = _spec_data()
    plain = parse_spec(data)
    assert plain.spec_hash == flange_space.spec.spec_hash  # unset: the hash does not move
    data["parts"]["S"]["bolt_time"] = 8
    spec = parse_spec(data)
    assert spec.part("S").bolt_time == 8.0 and spec.spec_hash != plain.spec_hash
    assert operator_seconds(spec, (), "S12") == 8.0
    assert operator_seconds(spec, ("S12",), "F01") == DEFAULT_BOLT_TIME
    assert operator_seconds(spec, ("S12",), "undo") == 8.0  # unbolting the square
    for bad in (0, -1, "5 s", True, float("inf")):
        data["parts"]["S"]["bolt_time"] = bad
        with pytest.raises(SpecError, match=r"parts\.S\.bolt_time: must be a positive number"):
            parse_spec(data)


def test_unit_costs_keep_the_four_sequences_tied(flange_space):
    states, _ = run_decisions(flange_space, exact_policy(flange_space))
    assert _names(flange_space, states) == "1 2 7 10"  # tie broken in the spec's token order


@pytest.mark.parametrize("config", [None, MdpConfig(gamma=1.0, mistake_prob=0.0), MdpConfig()])
def test_time_aware_policy_picks_the_fastest_of_the_four(flange_space, table, config):
    policy = exact_policy(flange_space, config, costs=table)
    states, _ = run_decisions(flange_space, policy)
    assert _names(flange_space, states) == "1 5 13 17"  # 34.05 s, the fastest
    assert policy.method == "exact/time"


@pytest.mark.parametrize("fastest", sorted(FOUR))
def test_time_aware_policy_follows_the_times(flange_space, fastest):
    robot = dict(ROBOT)
    by_name = {flange_space.sequence(s): flange_space.name(s) for s in range(flange_space.n_states)}
    seq = FOUR[fastest]
    for i in range(3):
        robot[by_name[seq[:i]], seq[i]] -= 0.5
    policy = exact_policy(flange_space, costs=_table(flange_space, robot))
    states, _ = run_decisions(flange_space, policy)
    assert _names(flange_space, states) == fastest


def test_time_aware_policy_recovers_fastest_after_a_deviation(flange_space, table):
    """After the operator places F3 (state 4), finishing S12, F01 is the only short way."""
    policy = exact_policy(flange_space, costs=table)
    assert policy.next_task(("F3",)) == "S12"
    # From 14 (F02 on the square, a mistake) undoing beats finishing into a wrong state.
    assert policy.next_task(("S12", "F02")) == "undo"


def test_edge_costs_and_task_costs_are_exclusive(flange_space, table):
    with pytest.raises(ValueError, match="not both"):
        Rewards(task_costs={"F1": 1.0}, edge_costs=table)
    incomplete = replace(table, entries={k: v for k, v in table.entries.items() if k[0]})
    with pytest.raises(KeyError, match="from state \\[\\]"):
        build_mdp(flange_space, timed_config(incomplete))


def test_q_learning_with_time_costs_learns_the_fastest(flange_space, table):
    """0.05 s between the two fastest of 34 s: the full schedule, without mistakes, resolves it."""
    mdp = build_mdp(flange_space, timed_config(table, MdpConfig(gamma=1.0, mistake_prob=0.0)))
    result = train(mdp, FullSchedule(), seed=0)
    policy = policy_from_choices(mdp, result.choice, "q-learning/explore")
    states, _ = run_decisions(flange_space, policy)
    assert _names(flange_space, states) == "1 5 13 17"


# --- Drake side: planned durations, the cell hash, the cache ---


@pytest.fixture(scope="module")
def planner(flange_space):
    pytest.importorskip("pydrake")
    from hrc_drake.cell.run.costs import timing_planner

    return timing_planner(flange_space)


def test_planned_edges_add_robot_and_bolting_time(flange_space, planner):
    from hrc_drake.cell.run.costs import compute_cost_table

    edges = [((), "F1"), (("F1",), "undo")]
    calls = []
    table = compute_cost_table(
        flange_space, planner, progress=lambda *a: calls.append(a), edges=edges
    )
    assert list(table.entries) == edges and [c[:2] for c in calls] == [(1, 2), (2, 2)]
    place, undo = table.cost((), "F1"), table.cost(("F1",), "undo")
    assert planner.options.hold_time == 0.0
    assert place.operator == undo.operator == DEFAULT_BOLT_TIME
    for cost in (place, undo):
        assert cost.seconds == pytest.approx(cost.robot + cost.operator)
    # Home to home with pick, carry, place and two 0.5 s gripper moves: seconds, not minutes.
    assert 3.0 < place.robot < 10.0
    # Putting the flange back moves the same part along the same places.
    assert undo.robot == pytest.approx(place.robot, abs=0.5)
    plan = planner.plan_task(frozenset(), "F1")
    assert place.robot == pytest.approx(plan.duration, abs=1e-3)


def test_planned_bets_and_carry_milestones(flange_space, planner):
    """A placement's carry runs from the lift's end to the pre-place pose; a re-target (the
    flange carried to seat 1, then on to 2 or 3) costs well under a second, a swap (the flange
    put back, then the square or the undo fetched) seconds: lowered, released, up, across."""
    from hrc_drake.cell.run.costs import bet_seconds, carry_milestones, compute_cost_table
    from hrc_drake.motion import Stage

    plan = planner.plan_task(frozenset(), "F1")
    start, end = carry_milestones(plan)
    carry = plan.segment(Stage.CARRY)
    assert carry.start < start < end == pytest.approx(carry.end, abs=1e-3)
    table = compute_cost_table(flange_space, planner, edges=[((), "F1"), (("F1",), "undo")])
    assert (table.cost((), "F1").carry_start, table.cost((), "F1").carry_end) == (start, end)
    assert table.cost(("F1",), "undo").carry_start is None and table.bets is None
    retargets = [bet_seconds(planner, flange_space, (), "F1", t) for t in ("F2", "F3")]
    swap = bet_seconds(planner, flange_space, (), "F1", "S12")
    undo = bet_seconds(planner, flange_space, ("F1",), "S23", "undo")
    put_back = 2 * planner.options.gripper_time  # at least: closed, then opened again
    assert all(0.0 <= r < 2.0 for r in retargets)
    assert max(retargets) + put_back < swap < 8.0 and put_back < undo < 8.0


class _Motion:
    def __init__(self, name: str, start: float, duration: float):
        self.name, self.start, self.duration = name, start, duration


class _Plan:
    """What `compute_cost_table` reads of a plan: its duration and its named motions (home to
    the pre-grasp 0-1.5 s, the lift 2-2.5 s, the carry 2.5-4 s)."""

    def __init__(self, duration: float):
        from hrc_drake.motion.plan import LIFT

        self.duration = duration
        self.motions = (
            _Motion("home to pre-grasp", 0.0, 1.5),
            _Motion(LIFT, 2.0, 0.5),
            _Motion("carry to pre-place", 2.5, 1.5),
        )


# Edges the stand-in planner cannot plan: a placement from the empty base and an undo from a
# wrong state (not terminal: runs take it).
NO_PLAN = {((), "F3"), (("F1", "S23", "F02"), "undo")}


@pytest.fixture
def unplannable(monkeypatch, flange_space):
    """`compute_cost_table` of the flange case with a stand-in planner (6 s per task, no plan
    for the `NO_PLAN` edges, none for the bet F1 -> F2 in the empty base), and the edges it
    was asked to plan."""
    from types import SimpleNamespace

    import hrc_drake.cell.run.costs as cell_costs
    from hrc_drake.motion import UnreachableError

    asked = []

    def plan_edge(planner, space, state, task):
        asked.append((tuple(state), task))
        if (tuple(state), task) in NO_PLAN:
            raise UnreachableError(task, "place", "minimum distance", "injected")
        return _Plan(6.0)

    def bet(planner, space, state, committed, indicated):
        if (state, committed, indicated) == ((), "F1", "F2"):
            raise UnreachableError(indicated, "pre-place", "position", "injected")
        return 0.7

    monkeypatch.setattr(cell_costs, "_plan_edge", plan_edge)
    monkeypatch.setattr(cell_costs, "bet_seconds", bet)
    monkeypatch.setattr(cell_costs, "check_reach", lambda planner: None)
    monkeypatch.setattr(cell_costs, "cell_hash", lambda planner: "stand-in")
    planner = SimpleNamespace(options=cell_costs.timing_options())
    return cell_costs.compute_cost_table(flange_space, planner), asked, planner


def test_a_cost_table_leaves_out_the_edges_no_run_takes(flange_space, unplannable):
    """Undo from a terminal state is in the state graph but in no run (a run ends there): the
    table neither plans nor holds it; nor a bet on a placement the robot cannot plan."""
    from hrc_drake.tasks.costs import bet_pairs, run_edges

    table, asked, _ = unplannable
    terminal = {s for s in range(flange_space.n_states) if flange_space.kind[s] == TERMINAL}
    left_out = [(s, t) for s, t in task_edges(flange_space) if flange_space.index(s) in terminal]
    assert len(left_out) == 4 and {t for _, t in left_out} == {"undo"}
    assert set(table.entries) == set(run_edges(flange_space)) and len(table) == 38 - 4
    assert not set(asked) & set(left_out) and table.missing(flange_space) == []
    # 42 bets in the graph; the four on F3 in the empty base are left out: never started on.
    assert set(table.bets) == set(bet_pairs(flange_space, NO_PLAN)) and len(table.bets) == 38
    assert not any(key[:2] == ((), "F3") for key in table.bets)


def test_an_edge_the_robot_cannot_plan_is_priced_as_the_operators(
    tmp_path, flange_space, unplannable
):
    from hrc_drake.cell.run.costs import HANDOVER_TIME
    from hrc_drake.tasks.bets import Bet

    table, _, planner = unplannable
    assert set(table.operator_edges()) == NO_PLAN
    cost = table.cost((), "F3")
    assert cost.by_operator and cost.robot is None and cost.carry_start is None
    assert (cost.handover, cost.operator) == (HANDOVER_TIME, DEFAULT_BOLT_TIME)
    assert cost.seconds == HANDOVER_TIME + DEFAULT_BOLT_TIME and "injected" in cost.reason
    assert not table.cost((), "F1").by_operator and table.cost((), "F1").robot == 6.0
    # F1 carried toward seat 1, the operator indicates F3: the part goes back (2.5 s to the
    # lift's end, lowered, released, up: 2 x 0.5 s + the gripper), then F3 is handed over.
    put_back = 2.5 + 2 * 0.5 + planner.options.gripper_time
    assert table.bet_kind(flange_space, (), "F1", "F3") == Bet.SWAP
    assert table.bets[(), "F1", "F3"] == pytest.approx(put_back)
    # A re-target whose own move cannot be planned: carried back along the carry, put back.
    assert table.bets[(), "F1", "F2"] == pytest.approx(put_back + 2 * 1.5)
    assert table.bets[(), "F1", "S12"] == 0.7

    path = tmp_path / "costs.json"
    save_cost_table(table, path)
    data = json.loads(path.read_text())
    assert data["version"] == 3
    entry = next(e for e in data["entries"] if e["state"] == [] and e["task"] == "F3")
    assert entry["by"] == "operator" and entry["handover"] == HANDOVER_TIME
    assert "robot" not in entry and "injected" in entry["reason"]
    loaded = load_cost_table(path, flange_space, cell_hash="stand-in")
    assert loaded.entries == table.entries and loaded.bets == table.bets
    # A scenario whose operator takes 2 s by hand prices the operator's edges so.
    quick = loaded.with_handover_time(2.0)
    assert quick.seconds((), "F3") == 2.0 + DEFAULT_BOLT_TIME
    assert quick.cost((), "F1") == loaded.cost((), "F1")


def test_deciders_and_runs_never_need_what_a_table_leaves_out(flange_space, unplannable):
    """The solver, every decider and task-level runs work with the table: they never ask for an
    edge from a terminal state, and never start on a task the robot cannot plan (they wait)."""
    from hrc_drake.evaluate import evaluate
    from hrc_drake.evaluation_runs import Setup
    from hrc_drake.tasks.deciders import DECIDERS, make_decider
    from hrc_drake.tasks.interaction import Interaction, InteractionCosts, Step

    table, _, _ = unplannable
    mdp = build_mdp(flange_space, timed_config(table))
    assert mdp.n_edges == len(table)  # one MDP action per edge the table holds
    bets = InteractionCosts(flange_space, table, Interaction())
    assert "F3" not in bets.bets(()) and {"F1", "F2", "S12", "S23"} <= set(bets.bets(()))
    assert bets.best_bet((), {"F3": 1.0}, "F3") == (None, bets.wait_seconds)
    assert bets.play((), "F3", "F3", 2.0) == Step(None, 2.0, 2.0)  # the robot waited
    # By hand in no time, F3 is the fastest first task: proposed, never started on.
    quick = table.with_handover_time(0.0)
    time_decider = make_decider("time", flange_space, quick, interaction=Interaction())
    assert time_decider.propose(()) == "F3" and time_decider.commit((), "F3") is None
    for name in DECIDERS:
        report = evaluate(Setup(flange_space, table, name, "random", {}, seed=1), runs=20)
        assert report["completed"] == 20, name


def test_cell_hash_names_the_options_and_frames(flange_space, planner):
    from hrc_drake.cell.run.costs import cell_hash, timing_options, timing_planner
    from hrc_drake.motion import MotionOptions, MotionPlanner

    assert cell_hash(planner) == cell_hash(timing_planner(flange_space))
    slower = MotionPlanner(
        options=replace(timing_options(), tcp_speed_limit=0.2),
        frames=planner.frames,
        q_home=planner.q_home,
    )
    assert cell_hash(slower) != cell_hash(planner)
    assert timing_options(MotionOptions(hold_time=3.0)).hold_time == 0.0


def test_default_cost_table_is_read_from_the_cache(tmp_path, flange_space, planner, table):
    from hrc_drake.cell.run.costs import cell_hash, default_cost_table

    key = cell_hash(planner)
    cached = replace(table, cell_hash=key)
    save_cost_table(cached, tmp_path / f"costs-{flange_space.spec.spec_hash}-{key}.json")
    loaded = default_cost_table(flange_space, planner, folder=tmp_path)
    assert loaded.entries == cached.entries and loaded.cell_hash == key


def test_cli_costs_solve_and_train(tmp_path, monkeypatch, capsys, flange_space, table):
    import hrc_drake.cli.costs as costs_command
    from hrc_drake.cli import main
    from hrc_drake.tasks.policy import load_policy

    # The planning itself is tested above; here the command around it, with the hand table.
    monkeypatch.setattr(costs_command, "timing_planner", lambda space: None)
    monkeypatch.setattr(costs_command, "compute_cost_table", lambda space, planner, progress: table)
    out = tmp_path / "costs.json"
    assert main(["costs", "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [r["states"] for r in report["shortest_sequences"]] == [
        "1 5 13 17", "1 4 8 11", "1 2 7 10", "1 6 16 20"
    ]  # fmt: skip
    assert report["time_aware_choice"]["states"] == "1 5 13 17"
    assert report["unit_cost_choice"]["states"] == "1 2 7 10"
    assert load_cost_table(out, flange_space).entries == table.entries

    policy_file = tmp_path / "time.json"
    assert main(["solve", "--costs", str(out), "--out", str(policy_file)]) == 0
    policy = load_policy(policy_file, flange_space)
    assert policy.method == "exact/time" and policy.next_task(()) == "S12"
    assert policy.meta["gamma"] == 1.0 and policy.meta["cell_hash"] == "test-cell"
    assert (
        main(["train", "--costs", str(out), "--schedule", "explore", "--out", str(policy_file)])
        == 0
    )
    assert load_policy(policy_file, flange_space).meta["schedule"] == "explore"

    out.write_text(out.read_text().replace('"seconds": 10.96', '"seconds": 1.0'))
    assert main(["solve", "--costs", str(out), "--out", str(policy_file)]) == 2
    assert "checksum mismatch" in capsys.readouterr().err


def test_cli_costs_prints_the_bets(tmp_path, monkeypatch, capsys, toy_costs):
    import hrc_drake.cli.costs as costs_command
    from hrc_drake.cli import main

    monkeypatch.setattr(costs_command, "timing_planner", lambda space: None)
    monkeypatch.setattr(
        costs_command, "compute_cost_table", lambda space, planner, progress: toy_costs
    )
    out = tmp_path / "costs.json"
    assert main(["costs", "--out", str(out), "--interface", "touch", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)["interaction"]
    assert report["interface"] == "touch" and report["delay"]["median"] == 2.5
    rows = {(tuple(b["state"]), b["committed"], b["indicated"]): b for b in report["bets"]}
    assert len(rows) == len(toy_costs.bets) == 42
    retarget, swap = rows[(), "F1", "F3"], rows[(), "F1", "S12"]
    assert (retarget["kind"], retarget["planned"], swap["kind"], swap["planned"]) == (
        "retarget", 0.8, "swap", 4.0,
    )  # fmt: skip
    # With the touch delay (median 2.5 s) the indication comes about when the carry starts.
    assert 0.0 < retarget["expected"] < 0.8 and 2.5 < swap["expected"] < 4.0 + 1.5
    assert report["wait_seconds"] == pytest.approx(2.5 * np.exp(0.045), abs=1e-3)
    assert main(["costs", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "42 bets" in text and "F1 -> S12   swap" in text and "waiting for the indication" in text
