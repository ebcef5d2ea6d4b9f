"""The task layer's commands: `states`, `solve`, `train`, `policy`, `check-policy`, `react`,
`table2` and `plot` (no Drake)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from hrc_drake.hri.operator import ScriptedOperator, parse_operator_script
from hrc_drake.memory import give_back_free_memory
from hrc_drake.paths import UsageError, check_output_path, image_kind
from hrc_drake.progress import ProgressLine
from hrc_drake.scenario.load import table2_scenarios
from hrc_drake.tasks.costs import CostTable, load_cost_table
from hrc_drake.tasks.decide import (
    DecisionError,
    InfeasibleTaskError,
    ScriptPastEndError,
    check_script_within_run,
    run_decisions,
)
from hrc_drake.tasks.graph import StateSpace, generate_states
from hrc_drake.tasks.learn import SCHEDULES, Schedule, train
from hrc_drake.tasks.listing import (
    policy_rows_json,
    policy_rows_text,
    sequences,
    state_rows_json,
    state_rows_text,
    write_json_list,
)
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import (
    POLICY_FILE,
    Policy,
    load_policy,
    next_states,
    policy_from_choices,
    save_policy,
)
from hrc_drake.tasks.policy_check import check_policy, exact_next_states, load_runnable_policy
from hrc_drake.tasks.solve import exact_policy, tasks_to_finish, timed_config
from hrc_drake.tasks.spec import load_spec


def _space(args) -> StateSpace:
    return generate_states(load_spec(args.assembly))


def _mdp_config(args, costs: CostTable | None = None) -> MdpConfig:
    # Unit rewards: the paper's discount. Seconds: undiscounted, the expected time to finish.
    gamma = args.gamma if args.gamma is not None else (0.95 if costs is None else 1.0)
    config = MdpConfig(gamma=gamma, mistake_prob=args.mistake_prob)
    return config if costs is None else timed_config(costs, config)


def _costs(args, space: StateSpace) -> CostTable | None:
    """The cost table of `--costs FILE` (None without it)."""
    path = getattr(args, "costs", None)
    return None if path is None else load_cost_table(path, space)


def _policy(args, space: StateSpace) -> Policy:
    """`--policy FILE` for a command that runs it (refused if it never finishes from some
    state, `load_runnable_policy`), else the exact policy."""
    if getattr(args, "policy", None):
        return load_runnable_policy(args.policy, space)
    return exact_policy(space, _mdp_config(args))


def _print_json(data) -> None:
    json.dump(data, sys.stdout, indent=1)
    sys.stdout.write("\n")


def cmd_states(args) -> int:
    """Print the state table (Table 1 for the flange case), row by row as it goes."""
    space = _space(args)
    best = tasks_to_finish(space)
    if args.json:
        write_json_list(sys.stdout, state_rows_json(space, best))
        return 0
    print(
        f"{space.spec.name}: {space.n_states} states, {len(np.unique(space.mask))} configurations"
    )
    print(f"{'#':>4}  {'sequence':<20} {'kind':<10} {'to finish':>9}  tasks")
    for line in state_rows_text(space, best):
        print(line)
    return 0


def cmd_solve(args) -> int:
    """Solve the MDP exactly and save the policy."""
    check_output_path(args.out, "--out", kind=POLICY_FILE, force=args.force)
    space = _space(args)
    costs = _costs(args, space)
    policy = exact_policy(space, _mdp_config(args, costs), costs=costs)
    save_policy(policy, args.out)
    print(f"exact policy for {space.spec.name!r} ({len(policy.table)} states) -> {args.out}")
    return 0


def _schedule(args) -> Schedule:
    return SCHEDULES[args.schedule]()


def cmd_train(args) -> int:
    """Q-learning with the paper's or our schedule; save the policy."""
    check_output_path(args.out, "--out", kind=POLICY_FILE, force=args.force)
    space = _space(args)
    costs = _costs(args, space)
    config = _mdp_config(args, costs)
    mdp = build_mdp(space, config)
    schedule = _schedule(args)
    unit = {"paper": "episode", "cover": "round"}.get(args.schedule, "sweep")
    with ProgressLine(f"training ({schedule.name})", unit) as bar:
        result = train(mdp, schedule, seed=args.seed, progress=bar.update)
    meta = {
        "seed": args.seed,
        "schedule": schedule.name,
        "episodes": result.episodes,
        "steps": result.steps,
        "gamma": config.gamma,
        "mistake_prob": config.mistake_prob,
    }
    if result.rounds:
        meta["rounds"] = result.rounds
        meta["converged"] = result.converged
    if costs is not None:
        meta["cell_hash"] = costs.cell_hash
    policy = policy_from_choices(mdp, result.choice, f"q-learning/{schedule.name}", meta)
    del mdp  # the MDP's arrays are not needed to write the file (at 10^6 states: 150 MB)
    give_back_free_memory()
    save_policy(policy, args.out)
    if not result.converged:
        print(
            f"hrc-drake train: warning: the {schedule.name} schedule stopped at its cap of "
            f"{result.rounds} rounds before every state was covered; `hrc-drake check-policy "
            f"--policy {args.out}` shows where the policy falls short",
            file=sys.stderr,
        )
    if args.json:
        _print_json(
            {
                "out": str(args.out),
                "assembly": space.spec.name,
                "states": space.n_states,
                **meta,
                "wall_time": round(result.wall_time, 3),
            }
        )
        return 0
    rounds = f" in {result.rounds} rounds" if result.rounds else ""
    print(
        f"{result.episodes} episodes, {result.steps} steps{rounds}, {result.wall_time:.2f} s "
        f"-> {args.out}"
    )
    return 0


def cmd_policy(args) -> int:
    """For every state: its sequence, kind, and the sequence after the proposed task; row by
    row, from the policy's next state per state (no dictionary of every sequence)."""
    space = _space(args)
    if getattr(args, "policy", None):
        next_state = next_states(space, load_policy(args.policy, space))
    else:
        next_state = exact_next_states(space, _mdp_config(args))
    if args.json:
        write_json_list(sys.stdout, policy_rows_json(space, next_state))
    else:
        for line in policy_rows_text(space, next_state):
            print(line)
    return 0


def cmd_check_policy(args) -> int:
    """Score a policy file against the exact solution: states where it is not minimum-effort,
    states from which it never finishes (it loops), and the value gap. Exit status 1 when it
    never finishes from some state (the commands that run a policy refuse it)."""
    space = _space(args)
    policy = load_policy(args.policy, space)
    method, next_state = policy.method, next_states(space, policy)
    del policy  # its table of sequences is not needed beside the solver's arrays
    costs = _costs(args, space)
    check = check_policy(space, next_state, _mdp_config(args, costs))
    summary = {
        "assembly": space.spec.name,
        "policy": str(args.policy),
        "method": method,
        **check.summary(),
    }
    bad = np.flatnonzero(check.not_minimum)
    if args.json:
        _print_check_json(space, check, summary, bad)
    else:
        _print_check(space, check, summary, bad)
    return 1 if check.unfinished.any() else 0


CHECK_SHOWN = 10  # states the text report lists (--json lists every one)


def _check_rows(space: StateSpace, check, states: np.ndarray):
    """(sequence, tasks or None when it never finishes, fewest, loops) of `states`."""
    steps, fewest = check.walks.steps[states].tolist(), check.fewest[states].tolist()
    loops = check.walks.loops[states].tolist()
    rows = zip(sequences(space, states), steps, fewest, loops, strict=True)
    for seq, k, b, lp in rows:
        yield seq, (k if k >= 0 else None), b, lp


def _print_check_json(space: StateSpace, check, summary: dict, bad: np.ndarray) -> None:
    """The summary, then `not_minimum_effort_states`: one compact row per state, written as
    they go (there may be as many as states)."""
    head = json.dumps(summary, indent=1)
    sys.stdout.write(head[:-2] + ',\n "not_minimum_effort_states": [')
    sep = "\n  "
    for seq, steps, fewest, loops in _check_rows(space, check, bad):
        row = {"sequence": seq, "tasks": steps, "fewest": fewest, "loops": loops}
        sys.stdout.write(sep + json.dumps(row))
        sep = ",\n  "
    sys.stdout.write("\n ]\n}\n" if len(bad) else "]\n}\n")


def _print_check(space: StateSpace, check, summary: dict, bad: np.ndarray) -> None:
    s = summary
    print(f"policy {s['policy']} ({s['method']}) on {s['assembly']}: {s['states']:,} states")
    print(
        f"minimum-effort from {s['minimum_effort']:,} of {s['non_terminal']:,} non-terminal "
        f"states; not from {s['not_minimum_effort']:,}, of which {s['loops']:,} loop"
        + (f" and {s['missing']:,} have no task" if s["missing"] else "")
    )
    start = s["start_tasks"]
    print(
        f"from the start: {'never finishes' if start is None else f'{start} tasks'} "
        f"(fewest {s['start_fewest']})"
    )
    gap = s.get("value_gap")
    if gap is not None:
        print(f"value gap (gamma {gap['gamma']}, mistake_prob {gap['mistake_prob']}): " + _gap(gap))
    shown = 0
    for seq, steps, fewest, loops in _check_rows(space, check, bad[:CHECK_SHOWN]):
        what = "loops" if loops else "never finishes" if steps is None else f"{steps} tasks"
        print(f"  {' '.join(seq) or '(start)':<30} {what}, fewest {fewest}")
        shown += 1
    if len(bad) > shown:
        print(f"  ... and {len(bad) - shown:,} more (--json lists every one)")


def _gap(gap: dict) -> str:
    def fmt(x):
        return "inf" if x is None else f"{x:.4g}"

    where = "" if gap["max_at"] is None else f" (at {' '.join(gap['max_at']) or '(start)'})"
    text = f"start {fmt(gap['start'])}, max {fmt(gap['max'])}{where}, mean {fmt(gap['mean'])}"
    if gap["infinite"]:
        text += f" over the others; infinite from {gap['infinite']:,} (it may never finish)"
    return text


def cmd_react(args) -> int:
    """Run the decision loop with a scripted operator."""
    space = _space(args)
    policy = _policy(args, space)
    script = parse_operator_script(args.operator)
    states, decisions = run_decisions(
        space, policy, ScriptedOperator(script), max_steps=args.max_steps
    )
    check_script_within_run(script, decisions)
    if args.json:
        _print_json(
            {
                "states": [list(s) for s in states],
                "names": [space.name(space.index(s)) for s in states],
            }
        )
    else:
        for d in decisions:
            who = "robot" if d.performed == d.proposed else "OPERATOR"
            print(f"step {d.step}: proposed {d.proposed:<5} performed {d.performed:<5} ({who})")
        print("states:", " ".join(space.name(space.index(s)) for s in states))
    return 0


def table2_rows(space: StateSpace, policy: Policy) -> list[dict]:
    """Table 2: per row, the published sequence, the minimum-effort one and this policy's.

    `compare` says how this policy's sequence relates to the minimum-effort one: ``same``,
    ``equally_short`` (another route of the same length), ``longer``, ``shorter`` (the
    scenario's expected column is not minimal for this spec), ``script_na`` (the row's script
    does not apply to this policy's route: the scripted task is not feasible when its step
    comes, or the route ends before it) or ``error``; the last two leave `policy` None and
    say why in `note`.
    """
    rows = []
    for scenario in table2_scenarios():
        ours, note = None, None
        try:
            states, decisions = run_decisions(space, policy, ScriptedOperator(scenario.script))
            check_script_within_run(scenario.script, decisions)
            ours = [space.name(space.index(s)) for s in states]
        except InfeasibleTaskError as err:
            note = (
                f"script n/a: the row's {err.task} at step {err.step} is not feasible in state "
                f"{space.name(space.index(err.state))}, which this policy's route reaches at "
                "that step"
            )
        except ScriptPastEndError as err:
            note = (
                f"script n/a: this policy's route ends after {err.steps} step(s), before "
                f"scripted step {min(err.late)}"
            )
        except DecisionError as err:
            note = f"error: {err}"
        minimum = list(scenario.minimum_effort)
        rows.append(
            {
                "row": scenario.table2_row,
                "scenario": scenario.name,
                "operator": scenario.description,
                "published": list(scenario.published),
                "minimum_effort": minimum,
                "policy": ours,
                "compare": _compare(ours, minimum, note),
                "note": note,
            }
        )
    return rows


def _compare(ours: list[str] | None, minimum: list[str], note: str | None) -> str:
    if ours is None:
        return "script_na" if note and note.startswith("script n/a") else "error"
    if ours == minimum:
        return "same"
    if len(ours) > len(minimum):
        return "longer"
    return "equally_short" if len(ours) == len(minimum) else "shorter"


_MARKS = {
    "same": "",
    "equally_short": "   (another, equally short)",
    "longer": "   <- longer",
    "shorter": "   <- shorter than the minimum-effort column: check the scenario's expectation",
    "script_na": "",
    "error": "",
}


def check_table2_spec(space: StateSpace) -> None:
    """UsageError unless `space` is the flange case's (the default spec): Table 2's scripts and
    published sequences are the flange's tasks and states, meaningless on another spec."""
    flange = load_spec()
    if space.spec.spec_hash != flange.spec_hash:
        source = space.spec.source
        raise UsageError(
            f"--assembly {source}: Table 2 belongs to the flange case (its rows script the "
            f"flange's tasks and name its states) and says nothing about {space.spec.name!r}; "
            f"drop --assembly, or script this spec with `hrc-drake react --assembly {source} "
            "--operator 1:TASK`"
        )


def cmd_table2(args) -> int:
    """Print Table 2: published, minimum-effort and this policy's sequences (flange case only)."""
    space = _space(args)
    check_table2_spec(space)
    policy = _policy(args, space)
    rows = table2_rows(space, policy)
    if args.json:
        _print_json(rows)
        return 0
    print(f"Table 2 ({policy.method} policy)")
    print(f"{'row':>3}  {'published':<20} {'minimum effort':<20} {'this policy':<20}")
    for r in rows:
        ours = r["note"] if r["policy"] is None else " ".join(r["policy"])
        print(
            f"{r['row']:>3}  {' '.join(r['published']):<20} "
            f"{' '.join(r['minimum_effort']):<20} {ours:<20}{_MARKS[r['compare']]}"
        )
    return 0


def cmd_plot(args) -> int:
    """Figure 8 (state graph) or Figure 9 (learning curve) as a PNG, PDF or SVG."""
    from hrc_drake.tasks import plots

    kind = image_kind(Path(args.out).suffix)
    check_output_path(args.out, "--out", suffixes=plots.FORMATS, kind=kind, force=args.force)
    space = _space(args)
    if args.what == "graph":
        plots.plot_state_graph(space, args.out)
    else:
        mdp = build_mdp(space, _mdp_config(args))
        result = train(mdp, _schedule(args), seed=args.seed)
        plots.plot_learning_curve(result, args.out)
    print(f"wrote {args.out}")
    return 0


__all__ = [
    "check_table2_spec",
    "cmd_check_policy",
    "cmd_plot",
    "cmd_policy",
    "cmd_react",
    "cmd_solve",
    "cmd_states",
    "cmd_table2",
    "cmd_train",
    "table2_rows",
]
