"""`hrc-drake`: the parser and `main` (the commands are in the modules beside this one).

Every command takes ``--assembly PATH`` or ``--assembly NAME`` (a spec under models/assemblies/,
as a scenario's ``assembly:``; default: the flange case) and ``--seed``; the ones that print data
take ``--json``; ``hrc-drake --version`` prints the package's version.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path

import hrc_drake
from hrc_drake.cli.adversary import add_adversary_parser
from hrc_drake.cli.evaluate import (
    add_evaluate_parser,
    add_interaction_flags,
    add_separation_flag,
)
from hrc_drake.cli.tasks import (
    cmd_check_policy,
    cmd_plot,
    cmd_policy,
    cmd_react,
    cmd_solve,
    cmd_states,
    cmd_table2,
    cmd_train,
)
from hrc_drake.hri.operator import OperatorScriptError
from hrc_drake.paths import UsageError
from hrc_drake.scenario.schema import ScenarioError, assembly_file
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.tasks.costs import CostTableError
from hrc_drake.tasks.decide import (
    DecisionError,
)
from hrc_drake.tasks.graph import UnknownStateError
from hrc_drake.tasks.learn import DEFAULT_SCHEDULE, SCHEDULES
from hrc_drake.tasks.policy import (
    PolicyFileError,
)
from hrc_drake.tasks.profile import ProfileError

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130  # the shell's status for a command ended by SIGINT (128 + 2)

DESCRIPTION = "`hrc-drake`: the command line of the task layer and the cell."


def assembly_argument(text: str) -> Path:
    """`--assembly`: a path to a spec, or the name of one under models/assemblies/, resolved as
    a scenario's `assembly:` is (`assembly_file`); an unknown name lists the known ones."""
    try:
        return assembly_file(text)
    except SpecError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix("assembly ")) from None


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
    """`--mistake-prob`: a probability in [0, 1) (NaN refused), as `discount`. 1 is refused
    too: an operator who always misplaces never finishes an assembly with a mistake-prone
    placement, and the MDP has no value there."""
    value = _number(text)
    if not 0.0 <= value < 1.0:  # False for NaN too
        raise argparse.ArgumentTypeError(
            f"{text} is not a mistake probability; give a number in [0, 1) (default 0.05; 1 "
            "would misplace every part and never finish)"
        )
    return value


def pace(text: str) -> float:
    """`--realtime PACE`, `--live PACE`: a real-time rate > 0 (NaN and infinity refused), as
    `discount`."""
    value = _number(text)
    if not 0.0 < value < float("inf"):  # False for NaN too
        raise argparse.ArgumentTypeError(
            f"{text} is not a pace; give a real-time rate > 0 (1, the default: the wall clock's)"
        )
    return value


def add_realtime_flag(p, what: str) -> None:
    """`--realtime [PACE]` on the parser `p` (`what`: the side it paces)."""
    p.add_argument(
        "--realtime",
        nargs="?",
        const=1.0,
        default=None,
        type=pace,
        metavar="PACE",
        help=f"real time instead of the lockstep: {what} paced to the wall clock at PACE times "
        "its speed (default 1), every channel at its device's rate, the newest reading taken "
        "(docs/hardware.md); start both sides with it",
    )


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


def cmd_costs(args) -> int:
    """Plan every task edge with the motion layer and save the cost table (seconds)."""
    from hrc_drake.cli.costs import costs_command

    return costs_command(args)


def cmd_simulate(args) -> int:
    """Run a scenario through the Drake cell (headless) and record it."""
    from hrc_drake.cell.link.lockstep import ScenarioMismatch, StationLinkError
    from hrc_drake.cell_models import CellModelError
    from hrc_drake.cli.simulate import simulate_command

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
    from hrc_drake.cell_models import CellModelError
    from hrc_drake.cli.simulate import check_assembly_matches
    from hrc_drake.cli.station import station_command

    check_assembly_matches(args)  # before the station is built, as simulate does
    try:
        return station_command(args)
    except CellModelError as err:
        print(f"hrc-drake station: error: {err}", file=sys.stderr)
        return EXIT_USAGE


def cmd_drivers(args) -> int:
    """Serve the scenario's real devices (its `drivers:` section) on LCM until Ctrl-C."""
    from hrc_drake.cli.drivers import drivers_command

    return drivers_command(args)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `hrc-drake`."""
    parser = argparse.ArgumentParser(prog="hrc-drake", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"hrc-drake {hrc_drake.__version__}")
    common = _common_flags()
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    def add(name, func, help_text):
        p = sub.add_parser(name, parents=[common], help=help_text)
        p.set_defaults(func=func)
        return p

    _add_task_commands(add)
    _add_simulate(add("simulate", cmd_simulate, "run a scenario in the Drake cell"))
    _add_station(add("station", cmd_station, "serve a scenario's simulated station over LCM"))
    _add_drivers(add("drivers", cmd_drivers, "serve a scenario's real UR3 and RG2 over LCM"))
    add_evaluate_parser(add)
    add_adversary_parser(add)
    return parser


def _common_flags() -> argparse.ArgumentParser:
    """The flags every command takes: the assembly, the seed, JSON, the MDP's discount and the
    operator's mistake probability."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--assembly",
        type=assembly_argument,
        default=None,
        help="assembly spec: a path, or a name under models/assemblies/ such as four-slot "
        "(default: flange)",
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
        help="probability in [0, 1) that the operator misplaces a part (spec `mistakes`)",
    )
    return common


def _add_task_commands(add) -> None:
    """The task layer's commands and `costs`, with `add(name, func, help)` of `build_parser`."""
    add("states", cmd_states, "the state table (Table 1)")
    costs_help = "cost table (hrc-drake costs): minimise seconds instead of tasks"
    out_help = "policy file to write (an existing file that is not a policy needs --force)"
    p = add("solve", cmd_solve, "exact policy -> file")
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument("--costs", type=Path, default=None, help=costs_help)
    add_force_flag(p)
    p = add("train", cmd_train, "Q-learned policy -> file")
    p.add_argument("--out", required=True, help=out_help)
    p.add_argument(
        "--schedule",
        choices=list(SCHEDULES),
        default=DEFAULT_SCHEDULE,
        help=f"learning schedule (default {DEFAULT_SCHEDULE}: exploring starts until every "
        "state is covered; paper: the published one; docs/tasks.md)",
    )
    p.add_argument("--costs", type=Path, default=None, help=costs_help)
    add_force_flag(p)
    p = add("costs", cmd_costs, "plan every edge and bet a run takes -> cost table file (seconds)")
    p.add_argument("--out", type=Path, required=True)
    add_force_flag(p)
    add_interaction_flags(p, "; prices the bets with the interface's delay")
    add("policy", cmd_policy, "the policy for every state").add_argument("--policy")
    p = add("check-policy", cmd_check_policy, "score a policy file against the exact solution")
    p.add_argument("--policy", required=True, help="policy file (hrc-drake solve or train)")
    p.add_argument("--costs", type=Path, default=None, help=costs_help)
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


def _add_scenario_flags(p, simulate: bool) -> None:
    """The flags that make the scenario, which `simulate` and `station` share (a station and
    its controller are started with the same ones)."""
    p.add_argument(
        "--scenario",
        default=None,
        help="scenario name in scenarios/ or a path (default: row1-optimal, or with --assembly "
        "an operator who follows the robot)"
        if simulate
        else "as for simulate",
    )
    p.add_argument(
        "--scenario-text",
        action="append",
        default=None,
        help='YAML merged over the scenario, e.g. "{motion: {hold_time: 1.0}}"; repeat it to '
        "merge several, in order"
        if simulate
        else "as for simulate",
    )
    p.add_argument(
        "--operator",
        default=None,
        help='operator script, e.g. "1:F3,2:S12"'
        if simulate
        else "the simulated operator's script, as for simulate",
    )
    p.add_argument(
        "--lean",
        action="store_true",
        help="0.5 s bolting holds (tests, previews); same as --scenario-text with LEAN"
        if simulate
        else "as for simulate",
    )


def _add_simulate(p) -> None:
    """`simulate`'s flags."""
    _add_scenario_flags(p, simulate=True)
    p.add_argument("--policy", type=Path, default=None, help="policy file (default: exact)")
    p.add_argument("--record", type=Path, default=None, help="Meshcat HTML recording to write")
    p.add_argument("--still", type=Path, default=None, help="PNG of the cell at --still-time")
    p.add_argument(
        "--still-time", type=float, default=None, help="simulated time of --still (default 10)"
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit 3 when the run's safety check fails: the arm inside S_p faster than ISO/TS "
        "15066 permits toward that body region, or a contact beyond its permissible force",
    )
    p.add_argument(
        "--live",
        nargs="?",
        const=1.0,
        default=None,
        type=pace,
        metavar="PACE",
        help="you are the operator: serve Meshcat (open the printed URL) and run at the wall "
        "clock's pace, or PACE times it (2: twice as fast, for a quick look); at every task "
        "boundary your click is the indication (anticipating, the robot starts on its proposal "
        "meanwhile; with --interaction wait it waits for it)",
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
    add_realtime_flag(p, "with --station-lcm, the controller")
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


def _add_lcm_flag(p) -> None:
    """`--lcm URL`, the bus `station` and `drivers` serve on."""
    p.add_argument(
        "--lcm",
        metavar="URL",
        default=None,
        help="LCM URL to serve on (default: the scenario's lcm_buses.default, "
        "udpm://239.241.129.92:20185?ttl=0 unless it says otherwise: this machine only)",
    )


def _add_station(p) -> None:
    """`station`'s flags."""
    _add_scenario_flags(p, simulate=False)
    _add_lcm_flag(p)
    p.add_argument(
        "--timeout",
        type=float,
        default=60.0,
        help="seconds to wait for the controller to come, and for each of its later messages "
        "(in real time: for its first commands; then 2 s of silence end the run)",
    )
    add_realtime_flag(p, "the station")
    p.set_defaults(policy=None)


def _add_drivers(p) -> None:
    """`drivers`' flags."""
    p.add_argument(
        "--scenario",
        default=None,
        help="scenario name in scenarios/ or a path, whose `drivers:` section puts the UR3 "
        "(!UrRtde) or the RG2 (!Rg2Modbus) on real hardware",
    )
    p.add_argument(
        "--scenario-text",
        action="append",
        default=None,
        help='YAML merged over the scenario, e.g. "{drivers: {rg2: !Rg2Modbus {host: 10.0.0.9}}}"; '
        "repeat it to merge several, in order",
    )
    _add_lcm_flag(p)


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
