"""`hrc-drake`: the command line of the task layer and the cell.

Every command takes ``--assembly PATH`` (default: the flange case) and ``--seed``; the ones that
print data take ``--json``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from pathlib import Path

from hrc_drake.evaluate_command import (
    add_evaluate_parser,
    add_interaction_flags,
    add_separation_flag,
)
from hrc_drake.hri.operator import OperatorScriptError, ScriptedOperator, parse_operator_script
from hrc_drake.hri.scenario import ScenarioError, table2_scenarios
from hrc_drake.paths import UsageError, check_output_path, image_kind
from hrc_drake.progress import ProgressLine
from hrc_drake.tasks.costs import CostTable, CostTableError, load_cost_table
from hrc_drake.tasks.decide import (
    DecisionError,
    InfeasibleTaskError,
    ScriptPastEndError,
    check_script_within_run,
    run_decisions,
)
from hrc_drake.tasks.graph import StateSpace, UnknownStateError, generate_states
from hrc_drake.tasks.learn import SCHEDULES, Schedule, train
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import (
    POLICY_FILE,
    Policy,
    PolicyFileError,
    load_policy,
    policy_from_choices,
    save_policy,
)
from hrc_drake.tasks.profile import ProfileError
from hrc_drake.tasks.solve import exact_policy, tasks_to_finish, timed_config
from hrc_drake.tasks.spec import SpecError, load_spec

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # the shell's status for a command ended by SIGINT (128 + 2)


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def discount(text: str) -> float:
    """`--gamma`: a discount in (0, 1]. Refused (exit 2, the flag named, before any work): 0 and
    below, above 1 (values would grow without bound) and NaN."""
    value = _number(text)
    if not 0.0 < value <= 1.0:  # False for NaN too
        raise argparse.ArgumentTypeError(
            f"{text} is not a discount; give a number in (0, 1] (0.95: the paper's; 1: "
            "undiscounted, with --costs)"
        )
    return value


def probability(text: str) -> float:
    """`--mistake-prob`: a probability in [0, 1] (NaN refused), as `discount`."""
    value = _number(text)
    if not 0.0 <= value <= 1.0:  # False for NaN too
        raise argparse.ArgumentTypeError(
            f"{text} is not a probability; give a number in [0, 1] (default 0.05)"
        )
    return value


def seed(text: str) -> int:
    """`--seed`: a whole number >= 0 (numpy's generators refuse negative seeds, which would be a
    traceback after the runs began)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text}: give a whole number >= 0")
    return value


class OneLineParser(argparse.ArgumentParser):
    """A command's parser whose errors are one line, ``hrc-drake solve: error: argument
    --gamma: ...``, exit 2: the message names the flag and the fix; the usage block argparse
    prints above it would bury that line (`hrc-drake CMD --help` shows the flags)."""

    def error(self, message: str):
        """Print `message` as one line on stderr and exit with status 2."""
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def add_force_flag(p) -> None:
    """Register `--force` on the parser `p` of a command that writes files."""
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing output file that is not of the kind this command writes",
    )


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
                "kind": space.state_kind(s).key,
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
        kind = r["kind"].replace("_", " ")
        print(
            f"{r['name']:>4}  {seq:<20} {kind:<10} {r['tasks_to_finish']:>9}  "
            f"{', '.join(r['tasks'])}"
        )
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
    if costs is not None:
        meta["cell_hash"] = costs.cell_hash
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
            {"sequence": list(seq), "kind": space.state_kind(s).key, "task": task, "next": nxt}
        )
    if args.json:
        _print_json(rows)
    else:
        for r in rows:
            seq = " ".join(r["sequence"]) or "(start)"
            print(f"{seq:<16} {r['kind'].replace('_', ' '):<10} -> {r['task'] or '-'}")
    return 0


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


def cmd_costs(args) -> int:
    """Plan every task edge with the motion layer and save the cost table (seconds)."""
    from hrc_drake.cell.costs import costs_command

    return costs_command(args)


def cmd_simulate(args) -> int:
    """Run a scenario through the Drake cell (headless) and record it."""
    from hrc_drake.cell.command import simulate_command
    from hrc_drake.cell.interface import ScenarioMismatch, StationLinkError
    from hrc_drake.cell_models import CellModelError

    try:
        return simulate_command(args)
    except (CellModelError, ScenarioMismatch) as err:
        # A station that serves another scenario: the two command lines must agree, as for
        # an option refused (the station exits 2 as well).
        print(f"hrc-drake simulate: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except StationLinkError as err:
        print(f"hrc-drake simulate: error: {err}", file=sys.stderr)
        return 1


def cmd_station(args) -> int:
    """Serve a scenario's simulated station over LCM (for `simulate --station-lcm`)."""
    from hrc_drake.cell.command import check_assembly_matches
    from hrc_drake.cell.remote import station_command
    from hrc_drake.cell_models import CellModelError

    check_assembly_matches(args)  # before the station is built, as simulate does
    try:
        return station_command(args)
    except CellModelError as err:
        print(f"hrc-drake station: error: {err}", file=sys.stderr)
        return EXIT_USAGE


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
    common.add_argument("--seed", type=seed, default=0, help="random seed, a whole number >= 0")
    common.add_argument("--json", action="store_true", help="print data as JSON")
    common.add_argument(
        "--gamma",
        type=discount,
        default=None,
        help="discount in (0, 1] (default 0.95; 1 with --costs)",
    )
    common.add_argument(
        "--mistake-prob",
        type=probability,
        default=0.05,
        help="probability in [0, 1] that the operator misplaces a part (spec `mistakes`)",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    def add(name, func, help_text):
        p = sub.add_parser(name, parents=[common], help=help_text)
        p.set_defaults(func=func)
        return p

    add("states", cmd_states, "the state table (Table 1)")
    costs_help = "cost table (hrc-drake costs): minimise seconds instead of tasks"
    out_help = "policy file to write (an existing file that is not a policy needs --force)"
    p = add("solve", cmd_solve, "exact policy -> file")
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument("--costs", type=Path, default=None, help=costs_help)
    add_force_flag(p)
    p = add("train", cmd_train, "Q-learned policy -> file")
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument("--schedule", choices=list(SCHEDULES), default="full")
    p.add_argument("--costs", type=Path, default=None, help=costs_help)
    add_force_flag(p)
    p = add("costs", cmd_costs, "plan every task edge and bet -> cost table file (seconds)")
    p.add_argument("--out", type=Path, required=True)
    add_force_flag(p)
    add_interaction_flags(p, "; prices the bets with the interface's delay")
    add("policy", cmd_policy, "the policy for every state").add_argument("--policy")
    p = add("react", cmd_react, "decision loop with a scripted operator")
    p.add_argument("--policy")
    p.add_argument("--operator", default="", help='e.g. "1:F3,2:S12"')
    p.add_argument("--max-steps", type=int, default=50)
    add("table2", cmd_table2, "Table 2 side by side").add_argument("--policy")
    p = add("plot", cmd_plot, "Figure 8 (graph) or 9 (learning)")
    p.add_argument("what", choices=["graph", "learning"])
    p.add_argument("--out", required=True)
    p.add_argument("--schedule", choices=list(SCHEDULES), default="paper")
    add_force_flag(p)
    p = add("simulate", cmd_simulate, "run a scenario in the Drake cell")
    p.add_argument(
        "--scenario",
        default=None,
        help="scenario name in scenarios/ or a path (default: row1-optimal, or with --assembly "
        "an operator who follows the robot)",
    )
    p.add_argument(
        "--scenario-text",
        default=None,
        help='YAML merged over the scenario, e.g. "{motion: {hold_time: 1.0}}"',
    )
    p.add_argument("--operator", default=None, help='operator script, e.g. "1:F3,2:S12"')
    p.add_argument("--policy", type=Path, default=None, help="policy file (default: exact)")
    p.add_argument("--record", type=Path, default=None, help="Meshcat HTML recording to write")
    p.add_argument(
        "--lean",
        action="store_true",
        help="0.5 s bolting holds (tests, previews); same as --scenario-text with LEAN",
    )
    p.add_argument("--still", type=Path, default=None, help="PNG of the cell at --still-time")
    p.add_argument(
        "--still-time", type=float, default=None, help="simulated time of --still (default 10)"
    )
    p.add_argument(
        "--live",
        action="store_true",
        help="you are the operator: serve Meshcat (open the printed URL) and run at the wall "
        "clock's pace; at every task boundary your click is the indication (anticipating, the "
        "robot starts on its proposal meanwhile; with --interaction wait it waits for it)",
    )
    p.add_argument(
        "--port",
        type=int,
        default=None,
        help="the port Meshcat serves with --live or --record (default: the first free from 7000)",
    )
    add_force_flag(p)
    p.add_argument(
        "--station-lcm",
        metavar="URL",
        default=None,
        help="run the controller against the station `hrc-drake station` serves on this LCM URL "
        "(e.g. udpm://239.241.129.92:20185?ttl=0), started with the same scenario options",
    )
    add_interaction_flags(
        p,
        " (sets the scenario's interaction): in anticipate mode the robot starts on its "
        "commitment while the indication, which the simulated operator gives after the "
        "interface's delay, is on its way, and turns if it names another task; in wait mode it "
        "waits for it",
    )
    add_separation_flag(p)
    p.add_argument(
        "--operator-profile",
        type=Path,
        default=None,
        metavar="FILE",
        help="the operator's profile (what they do when the robot proposes): loaded if FILE "
        "exists (refused if made for another assembly), learned from this run and saved "
        "atomically; the cell's robot does not use it yet",
    )
    p = add("station", cmd_station, "serve a scenario's simulated station over LCM")
    p.add_argument("--scenario", default=None, help="as for simulate")
    p.add_argument("--scenario-text", default=None, help="as for simulate")
    p.add_argument(
        "--operator", default=None, help="the simulated operator's script, as for simulate"
    )
    p.add_argument("--lean", action="store_true", help="as for simulate")
    p.add_argument(
        "--lcm",
        metavar="URL",
        default=None,
        help="LCM URL to serve on (default udpm://239.241.129.92:20185?ttl=0: this machine only)",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="seconds to wait for the controller to come, and for each of its later messages",
    )
    p.set_defaults(policy=None)

    add_evaluate_parser(add)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of `hrc-drake`."""
    args = build_parser().parse_args(argv)
    # A shell that starts a job in the background hands it SIGINT ignored, and Python then
    # leaves it ignored: Ctrl-C (or a SIGINT sent on purpose) would not end the command.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's final flush
        return code
    except KeyboardInterrupt:
        # The last resort: commands with partial results (simulate, evaluate) write them and
        # return 130 themselves; anything else stops here with one line and no traceback.
        print(f"hrc-drake {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return 1
    except (
        SpecError,
        ProfileError,
        PolicyFileError,
        OperatorScriptError,
        ScenarioError,
        DecisionError,
        UnknownStateError,
        UsageError,
        CostTableError,
    ) as err:
        print(f"hrc-drake {args.command}: error: {err}", file=sys.stderr)
        return EXIT_USAGE


def _quiet_stdout() -> None:
    """After the reader of stdout went away (`hrc-drake states | head`): send the rest nowhere.

    The way the Python documentation gives (library/signal.html, "Note on SIGPIPE"): point
    stdout at devnull so that the flush at exit does not raise again, then exit with status 1.
    """
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return  # not a real file (captured in tests): nothing will flush to the pipe
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)


if __name__ == "__main__":
    sys.exit(main())
