"""`hrc-drake costs`: plan every edge a run of an assembly can take in the cell, save the cost
table (`hrc_drake.cell.run.costs`) and rank its sequences; say which edges the robot cannot plan
(the operator's, by hand)."""

from __future__ import annotations

import json
import sys
import time

from hrc_drake.cell.run.costs import compute_cost_table, timing_planner
from hrc_drake.cell_models import CellModelError
from hrc_drake.cli.evaluate import interaction_from_flags
from hrc_drake.paths import UsageError, check_output_path
from hrc_drake.progress import ProgressLine
from hrc_drake.tasks.costs import COST_TABLE_FILE, cost_summary, save_cost_table
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import bet_summary
from hrc_drake.tasks.mdp import MdpConfig
from hrc_drake.tasks.spec import load_spec


def costs_command(args) -> int:
    """`hrc-drake costs --out FILE [--json]`: plan every edge, save the table, rank sequences.
    A layout the UR3 cannot reach is a one-line UsageError; an edge the robot cannot plan is
    the operator's (counted and listed with its reason)."""
    check_output_path(args.out, "--out", kind=COST_TABLE_FILE, force=getattr(args, "force", False))
    interaction = interaction_from_flags(args)
    space = generate_states(load_spec(args.assembly))
    start = time.perf_counter()
    try:
        planner = timing_planner(space)
        with ProgressLine("planning task edges and bets", "plan") as bar:
            table = compute_cost_table(space, planner, progress=bar.update)
    except CellModelError as err:
        raise UsageError(str(err)) from None
    wall = time.perf_counter() - start
    save_cost_table(table, args.out)
    config = MdpConfig(
        gamma=1.0 if args.gamma is None else args.gamma, mistake_prob=args.mistake_prob
    )
    summary = {
        "out": str(args.out),
        **cost_summary(space, table, config),
        "by_operator": [
            {"state": list(state), "task": task, "reason": table.cost(state, task).reason}
            for state, task in table.operator_edges()
        ],
        "interaction": bet_summary(space, table, interaction),
        "wall_time": round(wall, 2),
    }
    if args.json:
        json.dump(summary, sys.stdout, indent=1)
        sys.stdout.write("\n")
        return 0
    bets = len(table.bets or {})
    by_operator = summary["by_operator"]
    print(
        f"{summary['edges']} task edges and {bets} bets of {space.spec.name!r} planned in "
        f"{wall:.1f} s (cell {table.cell_hash}), {len(by_operator)} of the edges the "
        f"operator's (the robot cannot plan them) -> {args.out}"
    )
    _print_by_operator(by_operator)
    _print_summary(summary)
    return 0


def _print_by_operator(rows: list[dict]) -> None:
    """The edges the robot cannot plan: handed over at run time, priced as the operator's."""
    for r in rows:
        state = " ".join(r["state"]) or "(empty base)"
        print(f"  by the operator: {r['task']} from {state}: {r['reason']}")


def _print_summary(summary: dict) -> None:
    """The sequences ranked, the two policies' choices and the bets, as text."""
    print(
        "shortest sequences, fastest first (as proposed; expected with the operator's "
        f"{summary['mistake_prob']:.0%} mistakes):"
    )
    for r in summary["shortest_sequences"]:
        parts = " + ".join(f"{t:.2f}" for t in r["task_seconds"])
        print(
            f"  {r['states']:<12} {' '.join(r['tasks']):<14} {r['seconds']:7.2f} s  "
            f"({parts})  expected {r['expected_seconds']:.3f} s"
        )
    for key, label in (("time_aware_choice", "time-aware"), ("unit_cost_choice", "unit-cost")):
        c = summary[key]
        print(
            f"{label} choice: {c['states']} ({' '.join(c['tasks'])}), {c['seconds']:.2f} s, "
            f"expected {c['expected_seconds']:.3f} s"
        )
    _print_bets(summary["interaction"])


def _print_bets(interaction: dict) -> None:
    """The bets of `bet_summary`: planned at most, and added on average with the delay."""
    delay = interaction["delay"]
    print(
        f"interaction {interaction['mode']} over the {interaction['interface']} (delay "
        f"{delay['distribution']}, median {delay['median']} s, mean {delay['mean']} s): waiting "
        f"for the indication costs {interaction['wait_seconds']:.2f} s per boundary"
    )
    if interaction["bets"] is None:
        print("  no re-target or swap times in this table")
        return
    print("  bets (robot starts on the first, the operator indicates the second): planned at "
          "most, added on average with this delay")  # fmt: skip
    for b in interaction["bets"]:
        state = " ".join(b["state"]) or "(empty base)"
        print(
            f"  {state:<12} {b['committed']:>4} -> {b['indicated']:<5} {b['kind']:<8} "
            f"{b['planned']:5.2f} s  {b['expected']:5.2f} s"
        )


__all__ = ["costs_command"]
