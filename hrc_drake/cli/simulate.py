"""`hrc-drake simulate`: a scenario (or an assembly and an operator script) in the Drake cell."""

from __future__ import annotations

import json
import math
import socket
import sys
from dataclasses import dataclass

from hrc_drake.cell.run.run import run_scenario, scenario_policy
from hrc_drake.cli.scenario_args import scenario_from_args, scenario_options
from hrc_drake.hri.faults import FaultError, check_faults_within_run
from hrc_drake.hri.operator import ScriptedOperator
from hrc_drake.paths import MESHCAT_RECORDING, PNG_FILE, UsageError, check_output_path
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.decide import check_script_within_run, run_decisions
from hrc_drake.tasks.graph import StateSpace, generate_states
from hrc_drake.tasks.policy import Policy
from hrc_drake.tasks.protocols import ObservesTasks
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

EXIT_INTERRUPTED = 130  # the shell's status for a command ended by SIGINT (128 + 2)
EXIT_UNSAFE = 3  # --strict: the run's safety check failed (1: not done, 2: usage)
DEFAULT_STILL_TIME = 10.0  # s, simulated: `--still` without `--still-time`


def _known_decisions(scenario: Scenario, space, policy, live: bool):
    """The run's decisions when they are known in advance (a scripted or following operator,
    not live), else None."""
    if live or scenario.stochastic or scenario.operator.model or scenario.decider.name:
        return None  # a decider's proposals depend on what it learns along the run
    return run_decisions(space, policy, ScriptedOperator(scenario.script))[1]


def _check_still_time(still_time: float, scenario: Scenario, decisions) -> None:
    """Before the run: refuse a `--still-time` past the longest run (`run.max_sim_time`); when
    the tasks are known in advance (a scripted or following operator, not live), a time within
    their bolting holds is surely within the run; otherwise say at once that the run's length is
    known only at its end (the still is then not written)."""
    limit = scenario.run.max_sim_time
    if still_time > limit:
        raise UsageError(
            f"--still-time {still_time} s is past the end of the run: a run lasts at most "
            f"run.max_sim_time, {limit} s; choose a time within it"
        )
    if decisions is not None and still_time <= len(decisions) * scenario.motion.hold_time:
        return  # the holds alone last longer: the run is surely still going then
    print(
        f"note: --still-time {still_time} s: this run's length is known only when it ends; if it "
        "ends earlier, that is reported then and no still is written",
        file=sys.stderr,
    )


def _check_faults_within_run(scenario: Scenario, decisions) -> None:
    """Before the run: a fault's task must be within the run when its tasks are known in
    advance (a scripted or following operator, not live); otherwise say at once that a fault
    past the end is reported as never injected."""
    if not scenario.faults:
        return
    if decisions is None:
        print(
            "note: faults: this run's length is known only when it ends; a fault whose task "
            "it does not reach is reported as not injected",
            file=sys.stderr,
        )
        return
    try:
        check_faults_within_run(scenario.faults, scenario.name or "--scenario-text", len(decisions))
    except FaultError as err:
        raise UsageError(str(err)) from None


def _check_port(port: int) -> None:
    """UsageError unless Meshcat can serve `port`: 0 (any free port) or 1024-65535 (Drake's
    Meshcat refuses the privileged ones), and free now."""
    if port != 0 and not 1024 <= port <= 65535:
        raise UsageError(f"--port {port}: give 0 (any free port) or a port from 1024 to 65535")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind(("", port))
        except OSError as err:
            raise UsageError(
                f"--port {port}: cannot serve it ({err.strerror}); choose another port, or "
                "leave --port out for the first free one from 7000"
            ) from None


def simulate_command(args) -> int:
    """Run a scenario headless, print the decision steps and states, write the recording.

    Ctrl-C ends it with one line: during the simulation, once the recording and the summary
    (or `--json`) of what ran are written, marked interrupted; before it, with nothing
    written. (`main` has made SIGINT raise KeyboardInterrupt, as the run needs.)"""
    try:
        return _simulate(args)
    except KeyboardInterrupt:
        print("hrc-drake simulate: interrupted before the simulation began", file=sys.stderr)
        return EXIT_INTERRUPTED


@dataclass(frozen=True)
class CheckedRun:
    """What `simulate` checked before anything is simulated, handed on to the run: the
    scenario (loaded once), the state space of its spec (built once) and the policy."""

    scenario: Scenario
    space: StateSpace
    policy: Policy


def _run(args, checked: CheckedRun, record, still, live: bool, port):
    """The run: in this process, or (`--station-lcm URL`) the controller here against the
    station another process serves (`hrc-drake station`)."""
    scenario, space, policy = checked.scenario, checked.space, checked.policy
    url = getattr(args, "station_lcm", None)
    pace = getattr(args, "realtime", None)
    # A scenario's decider learns from every task as the cell observed it (`DeciderPolicy`).
    on_task = policy.observe if isinstance(policy, ObservesTasks) else None
    if url is None:
        return run_scenario(
            scenario, policy, record=record, progress=not live, still=still, live=live,
            port=port, on_task=on_task, space=space, pace=args.live,
        )  # fmt: skip
    if record is not None or still is not None or live:
        raise UsageError(
            "--station-lcm runs only the controller here; --record, --still and --live need "
            "the station in this process: drop them"
        )
    from hrc_drake.cell.link.remote import check_lcm_url, run_over_lcm
    from hrc_drake.cell.link.scenario_identity import ScenarioIdentity

    # What the station must serve: this scenario, shown with the options that made it.
    identity = ScenarioIdentity.of(scenario, scenario_options(args))
    url = check_lcm_url(url, "--station-lcm")
    return run_over_lcm(
        scenario,
        url,
        policy,
        progress=True,
        identity=identity,
        on_task=on_task,
        space=space,
        pace=pace,
    )


def _outputs(args):
    """The checked `--record` path and `(time, path)` of `--still` (None when not asked); an
    existing file of another kind is refused unless `--force`."""
    force = getattr(args, "force", False)
    record = None
    if args.record:
        record = check_output_path(
            args.record, "--record", (".html",), kind=MESHCAT_RECORDING, force=force
        )
    still = None
    if args.still is None and args.still_time is not None:
        raise UsageError(
            f"--still-time {args.still_time} without --still: add --still FILE.png to write the "
            "still at that time, or drop --still-time"
        )
    if args.still is not None:
        if args.still_time is None:
            args.still_time = DEFAULT_STILL_TIME  # later checks and the summary read it
        if not (math.isfinite(args.still_time) and args.still_time >= 0):
            raise UsageError(f"--still-time {args.still_time}: give a time >= 0 s")
        still = (
            args.still_time,
            check_output_path(args.still, "--still", (".png",), kind=PNG_FILE, force=force),
        )
    return record, still


def check_assembly_matches(args) -> None:
    """`--assembly` with `--scenario`: UsageError unless the scenario was written for the same
    assembly spec (compared by content, so a path to the same file passes). Otherwise the run
    would build the `--assembly` cell while the scenario's operator script, expected states and
    description speak of its own assembly's tasks."""
    if getattr(args, "assembly", None) is None or getattr(args, "scenario", None) is None:
        return
    from hrc_drake.scenario.load import load_scenario

    named = load_scenario(args.scenario)  # Drake-free; its own errors are one line
    theirs, ours = load_spec(named.assembly_path), load_spec(args.assembly)
    if theirs.spec_hash != ours.spec_hash:
        raise UsageError(
            f"--assembly {args.assembly}: scenario {args.scenario} is written for assembly "
            f"{named.assembly!r} ({theirs.source}), whose tasks its operator and expectations "
            "name; drop --assembly to run the scenario, or drop --scenario to run "
            f"{args.assembly} with an operator who follows the robot"
        )


def _policy(scenario: Scenario, space):
    """The scenario's decider (`decider:`, as `evaluate --cell` plays it; its cost table
    planned with a progress line the first time), else its policy file or the exact policy."""
    if not scenario.decider.name:
        return scenario_policy(scenario, space)
    from hrc_drake.cell.run.evaluate import decider_policy
    from hrc_drake.progress import ProgressLine

    label = f"cost table of {space.spec.name} (planned once, then cached)"
    with ProgressLine(label, "plan") as bar:
        return decider_policy(scenario, space, progress=bar.update)


def _checked_run(args, live: bool, still):
    """The scenario, its state space and its policy, with the operator's script checked
    against the decision loop before anything is simulated (an infeasible task, or steps past
    the end of the run)."""
    check_assembly_matches(args)
    scenario = scenario_from_args(args)
    space = generate_states(load_spec(scenario.assembly_path))
    for d in scenario.operator.deviations:
        if d.task != UNDO:
            space.spec.placement(d.task)
    policy = _policy(scenario, space)
    # One decision loop serves every check that needs the run's tasks (a scripted operator is
    # never stochastic: the scenario check refuses both).
    decisions = _known_decisions(scenario, space, policy, live)
    if scenario.script and decisions is not None:
        check_script_within_run(scenario.script, decisions)
    _check_faults_within_run(scenario, decisions)
    if still is not None:
        _check_still_time(args.still_time, scenario, decisions)
    return CheckedRun(scenario, space, policy)


def _profile(args, space: StateSpace):
    """`--operator-profile FILE`: the profile in FILE, or a new one when FILE does not exist
    (None without the flag); a one-line error for an unusable file or one made for another
    assembly, before anything is simulated."""
    path = getattr(args, "operator_profile", None)
    if path is None:
        return None
    from hrc_drake.tasks.profile import ProfileError, load_or_new_profile

    check_output_path(path, "--operator-profile", (".json",))
    try:
        return load_or_new_profile(path, space)
    except ProfileError as err:
        raise UsageError(f"--operator-profile: {err}") from None


def _save_profile(args, profile, result) -> None:
    """Learn the run's tasks (what the cell observed) into the profile file as it is now (other
    runs may have saved sessions since it was loaded) and save it, under the file's lock."""
    from hrc_drake.tasks.profile import ProfileError, update_profile

    try:
        profile = update_profile(args.operator_profile, profile.space, result.tasks)
    except ProfileError as err:  # the file was spoilt while this run went on
        raise UsageError(f"--operator-profile: {err}") from None
    print(
        f"operator profile: {profile.assemblies} assemblies learned -> {args.operator_profile}",
        file=sys.stderr,
    )


def _simulate(args) -> int:
    if getattr(args, "realtime", None) is not None and getattr(args, "station_lcm", None) is None:
        raise UsageError(
            "--realtime paces the controller against a station over LCM: add --station-lcm URL "
            "(and start the station with --realtime), or use --live for a paced run here"
        )
    record, still = _outputs(args)
    live = getattr(args, "live", None) is not None
    if getattr(args, "port", None) is not None and not (live or record is not None):
        raise UsageError(
            f"--port {args.port}: Meshcat serves only with --live or --record; add one of "
            "them, or drop --port"
        )
    if live and args.operator is not None:
        raise UsageError("--live with --operator: in a live run you are the operator; drop one")
    checked = _checked_run(args, live, still)
    scenario = checked.scenario
    profile = _profile(args, checked.space)
    port = getattr(args, "port", None)
    if port is not None:
        _check_port(port)
    result = _run(args, checked, record, still, live, port)
    if profile is not None:
        _save_profile(args, profile, result)
    problems = []
    if still is not None and result.sim_time < args.still_time:
        problems.append(
            f"--still-time {args.still_time} s is past the end of the run "
            f"({result.sim_time:.1f} s simulated); choose a time within it"
        )
    if args.json:
        json.dump(result.to_json(), sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        _print_summary(result, scenario)
    if result.interrupted:
        print(f"hrc-drake simulate: {result.error}", file=sys.stderr)
        return EXIT_INTERRUPTED
    for problem in problems:
        print(f"hrc-drake simulate: error: {problem}", file=sys.stderr)
    if result.error:
        print(f"hrc-drake simulate: error: {result.error}", file=sys.stderr)
        return 1
    if problems:
        return 2
    if not result.done:
        return 1
    if getattr(args, "strict", False) and not _check_passed(result):
        print(
            "hrc-drake simulate: --strict: the run's safety check failed: "
            f"the arm {result.safety_check.summary()}",
            file=sys.stderr,
        )
        return EXIT_UNSAFE
    return 0


def _check_passed(result) -> bool:
    """Whether the run's own safety check (if it had one: a run with a body) passed."""
    return result.safety_check is None or result.safety_check.passed


def operator_summary(tasks) -> str:
    """What the operator did in a run's tasks (`TaskRecord`s): followed every proposal, or the
    steps where it performed another task (a deviation, or a part misplaced on another seat)."""
    if not tasks:
        return "no task was done"
    other = [t for t in tasks if t.indicated != t.proposed]
    if not other:
        return f"followed the robot's proposal at every step ({len(tasks)})"
    steps = ", ".join(f"step {t.step} {t.indicated} instead of {t.proposed}" for t in other)
    return f"performed another task than proposed at {len(other)} of {len(tasks)} steps: {steps}"


def _print_summary(result, scenario) -> None:
    print(f"scenario {result.scenario}: {scenario.description}")
    for t in result.tasks:
        who = "" if t.indicated == t.proposed else f" (operator: {t.indicated})"
        print(
            f"  step {t.step}: robot proposes {t.proposed}{who}; cell shows {t.observed}; "
            f"{t.end_time - t.start_time:.1f} s simulated"
        )
    print(f"  operator: {operator_summary(result.tasks)}")
    print("  states:", " ".join(result.names), f"({result.final_kind})")
    print(
        f"  {result.sim_time:.1f} s simulated in {result.wall_time:.1f} s "
        f"(real-time factor {result.real_time_factor or 0:.2f})"
    )
    if result.safety is not None:
        # The run's own check in words (`hrc_drake.cell.run.safety_check`), then the
        # monitor's figures.
        monitor = result.safety.to_json()
        if result.safety_check is not None:
            print(f"  safety: the arm {result.safety_check.summary()}")
        print(
            f"  separation {result.separation}: least {monitor['min_separation']} m, "
            f"slowed {monitor['slowed_time']} s, stopped {monitor['stopped_time']} s "
            f"(added {monitor['ssm_delay']} s)"
            + (f", waited {result.waited:.1f} s where it planned to" if result.waited else "")
        )
    if result.realtime is not None:
        paced = result.realtime.to_json()
        print(
            f"  real time: an update every {paced['period'] * 1000:.2f} ms "
            f"(target {paced['target_period'] * 1000:g}), jitter p99 "
            f"{paced['jitter']['p99'] * 1000:.2f} ms, {paced['missed_deadlines']} missed "
            f"deadline(s), pace {paced['pace_achieved']:.2f} of {paced['pace']:g}, "
            f"{paced['stale_stops']} stop(s) on stale readings"
        )
    if result.collisions:
        print("  unexpected contacts:", *result.collisions[:5], sep="\n    ")
    if result.recording:
        print(f"  recording: {result.recording} (open it in a web browser)")
