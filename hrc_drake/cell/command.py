"""`hrc-drake simulate`: a scenario (or an assembly and an operator script) in the Drake cell."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from hrc_drake.cell.run import run_scenario, scenario_policy
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.hri.operator import ScriptedOperator
from hrc_drake.hri.scenario import Scenario, with_operator_script
from hrc_drake.paths import UsageError, check_output_path
from hrc_drake.tasks.decide import check_script_within_run, run_decisions
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

DEFAULT_SCENARIO = "row1-optimal"


def _scenario(args) -> Scenario:
    overrides = [t for t in (LEAN if args.lean else None, args.scenario_text) if t]
    name = args.scenario
    if name is None and args.assembly is None:
        name = DEFAULT_SCENARIO
    scenario = load_cell_scenario(name, overrides)
    if args.assembly is not None:
        # A missing file is refused by `load_spec`, before anything is built.
        scenario = dataclasses.replace(scenario, assembly=str(args.assembly))
        if args.scenario is None:
            scenario.name = Path(args.assembly).stem
            scenario.description = f"assembly {args.assembly}, operator follows the robot"
    if args.operator is not None:
        scenario = with_operator_script(scenario, args.operator)
    if args.policy is not None:
        scenario = dataclasses.replace(scenario, policy=str(args.policy))
    return scenario


def simulate_command(args) -> int:
    """Run a scenario headless, print the decision steps and states, write the recording."""
    record = check_output_path(args.record, "--record", (".html",)) if args.record else None
    still = None
    if args.still is not None:
        if args.still_time < 0:
            raise UsageError(f"--still-time {args.still_time}: give a time >= 0 s")
        still = (args.still_time, check_output_path(args.still, "--still", (".png",)))
    if getattr(args, "live", False) and args.operator is not None:
        raise UsageError("--live with --operator: in a live run you are the operator; drop one")
    scenario = _scenario(args)
    space = generate_states(load_spec(scenario.assembly_path))
    for d in scenario.operator.deviations:
        if d.task != UNDO:
            space.spec.placement(d.task)
    policy = scenario_policy(scenario, space)
    live = getattr(args, "live", False)
    if scenario.script and not live:
        # The decision loop predicts a scripted run; refuse a script that cannot apply before
        # simulating it (an infeasible task, or steps past the end of the run).
        _, decisions = run_decisions(space, policy, ScriptedOperator(scenario.script))
        check_script_within_run(scenario.script, decisions)
    result = run_scenario(
        scenario, policy, record=record, progress=not live, still=still, live=live
    )
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
        print(f"scenario {result.scenario}: {scenario.description}")
        for t in result.tasks:
            who = "" if t.indicated == t.proposed else f" (operator: {t.indicated})"
            print(
                f"  step {t.step}: robot proposes {t.proposed}{who}; cell shows {t.observed}; "
                f"{t.end_time - t.start_time:.1f} s simulated"
            )
        print("  states:", " ".join(result.names), f"({result.final_kind})")
        print(
            f"  {result.sim_time:.1f} s simulated in {result.wall_time:.1f} s "
            f"(real-time factor {result.real_time_factor or 0:.2f})"
        )
        if result.safety is not None:
            figures = result.safety.to_json()
            print(
                f"  safety: least separation {figures['min_separation']} m, "
                f"{figures['violations']} violation(s), slowed {figures['slowed_time']} s, "
                f"stopped {figures['stopped_time']} s"
            )
        if result.collisions:
            print("  unexpected contacts:", *result.collisions[:5], sep="\n    ")
        if result.recording:
            print(f"  recording: {result.recording} (open it in a web browser)")
    for problem in problems:
        print(f"hrc-drake simulate: error: {problem}", file=sys.stderr)
    if result.error:
        print(f"hrc-drake simulate: error: {result.error}", file=sys.stderr)
        return 1
    if problems:
        return 2
    return 0 if result.done else 1
