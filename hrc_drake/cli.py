"""`hrc-drake`: the command line of the task layer and the cell.

Every command takes ``--assembly PATH`` (default: the flange case) and ``--seed``; the ones that
print data take ``--json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hrc_drake.hri.operator import OperatorScriptError, ScriptedOperator, parse_operator_script
from hrc_drake.hri.scenario import ScenarioError, table2_scenarios
from hrc_drake.progress import ProgressLine
from hrc_drake.tasks.decide import DecisionError, run_decisions
from hrc_drake.tasks.graph import StateSpace, UnknownStateError, generate_states
from hrc_drake.tasks.learn import FullSchedule, PaperSchedule, train
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import (
    Policy,
    PolicyFileError,
    load_policy,
    policy_from_choices,
    save_policy,
)
from hrc_drake.tasks.solve import exact_policy, tasks_to_finish
from hrc_drake.tasks.spec import SpecError, load_spec

EXIT_USAGE = 2


def _space(args) -> StateSpace:
    return generate_states(load_spec(args.assembly))


def _mdp_config(args) -> MdpConfig:
    return MdpConfig(gamma=args.gamma, mistake_prob=args.mistake_prob)


def _policy(args, space: StateSpace) -> Policy:
    if getattr(args, "policy", None):
        return load_policy(args.policy, space)
    return exact_policy(space, _mdp_config(args))


def _print_json(data) -> None:
    json.dump(data, sys.stdout, indent=1)
    sys.stdout.write("\n")


def cmd_states(args) -> int:
    """Print the state table (Table 1 for the flange case)."""
    space = _space(args)
    best = tasks_to_finish(space)
    rows = []
    for s in range(space.n_states):
        rows.append(
            {
                "name": space.name(s),
                "sequence": list(space.sequence(s)),
                "configuration": sorted(space.configuration(s)),
                "kind": space.state_kind(s).label,
                "tasks": [t for t, _ in space.tasks(s)],
                "actions": sorted({space.action_label(t) for t, _ in space.tasks(s)}),
                "tasks_to_finish": int(best[s]),
            }
        )
    if all(r["name"].isdigit() for r in rows):
        rows.sort(key=lambda r: int(r["name"]))
    if args.json:
        _print_json(rows)
        return 0
    print(
        f"{space.spec.name}: {space.n_states} states, {len(space.configurations())} configurations"
    )
    print(f"{'#':>4}  {'sequence':<20} {'kind':<10} {'to finish':>9}  tasks")
    for r in rows:
        seq = " ".join(r["sequence"]) or "(empty base)"
        print(
            f"{r['name']:>4}  {seq:<20} {r['kind']:<10} {r['tasks_to_finish']:>9}  "
            f"{', '.join(r['tasks'])}"
        )
    return 0


def cmd_solve(args) -> int:
    """Solve the MDP exactly and save the policy."""
    space = _space(args)
    policy = exact_policy(space, _mdp_config(args))
    save_policy(policy, args.out)
    print(f"exact policy for {space.spec.name!r} ({len(policy.table)} states) -> {args.out}")
    return 0


def _schedule(args):
    return PaperSchedule() if args.schedule == "paper" else FullSchedule()


def cmd_train(args) -> int:
    """Q-learning with the paper's or our schedule; save the policy."""
    space = _space(args)
    config = _mdp_config(args)
    mdp = build_mdp(space, config)
    schedule = _schedule(args)
    unit = "episode" if args.schedule == "paper" else "sweep"
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
    policy = policy_from_choices(mdp, result.choice, f"q-learning/{schedule.name}", meta)
    save_policy(policy, args.out)
    print(
        f"{result.episodes} episodes, {result.steps} steps, {result.wall_time:.2f} s -> {args.out}"
    )
    return 0


def cmd_policy(args) -> int:
    """For every state: its sequence, kind, and the sequence after the proposed task."""
    space = _space(args)
    policy = _policy(args, space)
    rows = []
    for s in range(space.n_states):
        seq = space.sequence(s)
        task = policy.next_task(seq)
        nxt = None
        if task is not None:
            nxt = list(space.sequence(dict(space.tasks(s))[task]))
        rows.append(
            {"sequence": list(seq), "kind": space.state_kind(s).label, "task": task, "next": nxt}
        )
    if args.json:
        _print_json(rows)
    else:
        for r in rows:
            seq = " ".join(r["sequence"]) or "(start)"
            print(f"{seq:<16} {r['kind']:<10} -> {r['task'] or '-'}")
    return 0


def cmd_react(args) -> int:
    """Run the decision loop with a scripted operator."""
    space = _space(args)
    policy = _policy(args, space)
    operator = ScriptedOperator(parse_operator_script(args.operator))
    states, decisions = run_decisions(space, policy, operator, max_steps=args.max_steps)
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
    """Table 2: per row, the published sequence, the minimum-effort one and this policy's."""
    rows = []
    for scenario in table2_scenarios():
        try:
            states, _ = run_decisions(space, policy, ScriptedOperator(scenario.script))
            ours = [space.name(space.index(s)) for s in states]
        except DecisionError as err:
            ours = [f"error: {err}"]
        rows.append(
            {
                "row": scenario.table2_row,
                "scenario": scenario.name,
                "operator": scenario.description,
                "published": list(scenario.published),
                "minimum_effort": list(scenario.minimum_effort),
                "policy": ours,
            }
        )
    return rows


def cmd_table2(args) -> int:
    """Print Table 2: published, minimum-effort and this policy's sequences."""
    space = _space(args)
    policy = _policy(args, space)
    rows = table2_rows(space, policy)
    if args.json:
        _print_json(rows)
        return 0
    print(f"Table 2 ({policy.method} policy)")
    print(f"{'row':>3}  {'published':<20} {'minimum effort':<20} {'this policy':<20}")
    for r in rows:
        mark = ""
        if r["policy"] != r["minimum_effort"]:
            same = len(r["policy"]) == len(r["minimum_effort"])
            mark = "   (another, equally short)" if same else "   <- longer"
        print(
            f"{r['row']:>3}  {' '.join(r['published']):<20} "
            f"{' '.join(r['minimum_effort']):<20} {' '.join(r['policy']):<20}{mark}"
        )
    return 0


def cmd_plot(args) -> int:
    """Figure 8 (state graph) or Figure 9 (learning curve) as a PNG."""
    from hrc_drake.tasks import plots

    space = _space(args)
    if args.what == "graph":
        plots.plot_state_graph(space, args.out)
    else:
        mdp = build_mdp(space, _mdp_config(args))
        result = train(mdp, _schedule(args), seed=args.seed)
        plots.plot_learning_curve(result, args.out)
    print(f"wrote {args.out}")
    return 0


def cmd_simulate(args) -> int:
    """Run a scenario through the Drake cell (headless) and record it."""
    from hrc_drake.cell.run import simulate_command

    return simulate_command(args)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `hrc-drake`."""
    parser = argparse.ArgumentParser(prog="hrc-drake", description=__doc__.split("\n")[0])
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--assembly",
        type=Path,
        default=None,
        help="assembly spec (default: models/assemblies/flange.yaml)",
    )
    common.add_argument("--seed", type=int, default=0)
    common.add_argument("--json", action="store_true", help="print data as JSON")
    common.add_argument("--gamma", type=float, default=0.95, help="discount")
    common.add_argument(
        "--mistake-prob",
        type=float,
        default=0.05,
        help="probability that the operator misplaces a part (spec `mistakes`)",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    def add(name, func, help_text):
        p = sub.add_parser(name, parents=[common], help=help_text)
        p.set_defaults(func=func)
        return p

    add("states", cmd_states, "the state table (Table 1)")
    add("solve", cmd_solve, "exact policy -> file").add_argument("--out", required=True)
    p = add("train", cmd_train, "Q-learned policy -> file")
    p.add_argument("--out", required=True)
    p.add_argument("--schedule", choices=["paper", "full"], default="full")
    add("policy", cmd_policy, "the policy for every state").add_argument("--policy")
    p = add("react", cmd_react, "decision loop with a scripted operator")
    p.add_argument("--policy")
    p.add_argument("--operator", default="", help='e.g. "1:F3,2:S12"')
    p.add_argument("--max-steps", type=int, default=50)
    add("table2", cmd_table2, "Table 2 side by side").add_argument("--policy")
    p = add("plot", cmd_plot, "Figure 8 (graph) or 9 (learning)")
    p.add_argument("what", choices=["graph", "learning"])
    p.add_argument("--out", required=True)
    p.add_argument("--schedule", choices=["paper", "full"], default="paper")
    p = add("simulate", cmd_simulate, "run a scenario in the Drake cell")
    p.add_argument("--scenario", default="row1-optimal")
    p.add_argument("--policy")
    p.add_argument("--record", type=Path, default=None, help="Meshcat HTML recording to write")
    p.add_argument("--lean", action="store_true", help="fast settings (tests, previews)")
    p.add_argument("--still", type=Path, default=None, help="PNG of the cell at --still-time")
    p.add_argument("--still-time", type=float, default=10.0, help="simulated time of --still")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `hrc-drake`."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (
        SpecError,
        PolicyFileError,
        OperatorScriptError,
        ScenarioError,
        DecisionError,
        UnknownStateError,
    ) as err:
        print(f"hrc-drake {args.command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
