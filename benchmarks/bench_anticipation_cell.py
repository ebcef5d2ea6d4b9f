"""The cell anticipating against the cell waiting -> benchmarks/reports/anticipation_cell.md.

The same runs twice, `interaction.mode: anticipate` and `wait`, per interface (`pointer`,
`gesture`, `touch`: their indication delays, drawn per step from the same seed in both modes), on
the flange case (Table 2's row 1 and row 8: the operator follows the robot; row 8's operator
mounts F3 where the robot proposed F1, so the robot re-targets) and the 4-slot and 5-slot cells
(the operator follows); the three-oval cell and Table 2's other rows (their operators force other
tasks: re-targets and swaps) over the pointer. Full settings: 5 s bolting holds, TCP <= 0.25
m/s, the operator's body and the separation monitor on.

Per run: the assembly's simulated seconds in each mode, the indication delay `wait` spends (per
step, from the prompt to the indication, summed), and the share of it anticipation saves:
(T_wait - T_anticipate) / delay. Also re-targets, swaps, collisions and separation violations.
Beside each cell time, the task level's on the same run
(`hrc_drake.cell.run.evaluate.task_level_run`: the cell's cost table, planned by the motion layer
and cached, the same operator and the same delay draws) and the ratio of the two: how far the task
level mirrors the cell.

Usage: ``python benchmarks/bench_anticipation_cell.py [--workers 2] [--lean]`` (with ``--lean``
the report is printed, not written).
"""

from __future__ import annotations

import argparse
import multiprocessing
import platform
import sys
from pathlib import Path

from cell_pool import pooled_loop, publish, run_pool

CELLS = {
    "flange row 1": ("row1-optimal", ""),
    "flange row 8": ("row8-forces-4-then-8", ""),
    "four-slot": (None, "{assembly: four-slot, name: four-slot}"),
    "five-slot": (None, "{assembly: five-slot, name: five-slot}"),
    "three-oval": (None, "{assembly: three-oval, name: three-oval}"),
    "flange row 2": ("row2-forces-2", ""),
    "flange row 3": ("row3-forces-3", ""),
    "flange row 4": ("row4-forces-4", ""),
    "flange row 5": ("row5-forces-5", ""),
    "flange row 6": ("row6-forces-6", ""),
    "flange row 7": ("row7-forces-9", ""),
    "flange row 9": ("row9-forces-5-then-14", ""),
}
INTERFACES = ("pointer", "gesture", "touch")
EVERY_INTERFACE = ("flange row 1", "flange row 8", "four-slot", "five-slot")


def interfaces(cell: str) -> tuple[str, ...]:
    """The interfaces a cell is run over: all of them, or the pointer."""
    return INTERFACES if cell in EVERY_INTERFACE else ("pointer",)


MODES = ("anticipate", "wait")
REPORT = Path(__file__).parent / "reports" / "anticipation_cell.md"
DROPPED, UNSEATED = "is not in the gripper", "does not sit in its seat"  # recovery.py's events


def run_scenario_of(job: tuple[str, str, str, bool]):
    """The scenario of a job: a cell in a mode over an interface."""
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    cell, interface, mode, lean = job
    name, text = CELLS[cell]
    texts = [t for t in (text, LEAN if lean else "") if t]
    texts.append(f"{{interaction: {{mode: {mode}, interface: {interface}}}}}")
    return load_cell_scenario(name, texts)


def one_run(job: tuple[str, str, str, bool]) -> dict:
    """One run of a cell in a mode over an interface: its figures."""
    from hrc_drake.cell.run.run import scenario_policy
    from hrc_drake.tasks.decide import run_decisions
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    cell, interface, mode, _lean = job
    scenario = run_scenario_of(job)
    space = generate_states(load_spec(scenario.assembly_path))
    react, _ = run_decisions(
        space, scenario_policy(scenario, space), scenario.operator_for(space).operator
    )
    result = pooled_loop(scenario, cell).run()
    delay, prompt = 0.0, 0.0
    for task in result.tasks:  # each prompt comes as the task before ends
        delay += task.indicated_at - prompt
        prompt = task.end_time
    safety = result.safety
    return {
        "cell": cell,
        "interface": interface,
        "mode": mode,
        "terminal": result.done,
        "states": [list(s) for s in result.states],
        "react": [list(s) for s in react] == [list(s) for s in result.states],
        "seconds": result.sim_time,
        "delay": delay,
        "retargets": sum(t.retargeted for t in result.tasks),
        "swaps": sum(t.swapped for t in result.tasks),
        "collisions": len(result.collisions),
        "violations": result.safety_check.violations if safety is not None else 0,
        "error": result.error,
        # A part out of the gripper in the carry, or let go out of its seat, as the Supervisor
        # found it from the gripper and the configuration sensor.
        "drops": sum(DROPPED in e or UNSEATED in e for e in result.events),
    }


def add_task_level(runs: list[dict], jobs: list) -> None:
    """Each run's task-level seconds (`task`), from its cell's cost table (computed once and
    cached by `default_cost_table`, here in this process)."""
    from hrc_drake.cell.run.costs import default_cost_table
    from hrc_drake.cell.run.evaluate import task_level_run
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    tables = {}
    for run, job in zip(runs, jobs, strict=True):
        scenario = run_scenario_of(job)
        if run["cell"] not in tables:
            space = generate_states(load_spec(scenario.assembly_path))
            tables[run["cell"]] = space, default_cost_table(space)
        space, costs = tables[run["cell"]]
        run["task"] = task_level_run(scenario, space, costs).seconds


def rows(runs: list[dict]) -> list[str]:
    """One report row per cell and interface: the two modes side by side."""
    out = []
    for cell in CELLS:
        for interface in interfaces(cell):
            pair = {r["mode"]: r for r in runs if r["cell"] == cell and r["interface"] == interface}
            a, w = pair["anticipate"], pair["wait"]
            saved = w["seconds"] - a["seconds"]
            share = saved / w["delay"] if w["delay"] > 0 else float("nan")
            same = "yes" if a["react"] and w["react"] else "no"
            out.append(
                f"| {cell} | {interface} | {a['seconds']:.2f} | {a['task']:.2f} | "
                f"{a['seconds'] / a['task']:.3f} | {w['seconds']:.2f} | {w['task']:.2f} | "
                f"{w['seconds'] / w['task']:.3f} | "
                f"{w['delay']:.2f} | {saved:.2f} | {100 * share:.0f} % | {a['retargets']} | "
                f"{a['swaps']} | {same} | {'yes' if a['terminal'] and w['terminal'] else 'no'} | "
                f"{a['collisions'] + w['collisions']} | {a['violations'] + w['violations']} | "
                f"{a['drops'] + w['drops']} |"
            )
    return out


def agreement(runs: list[dict]) -> str:
    """The ratios' range, and whether every run is within 5 %."""
    ratios = [r["seconds"] / r["task"] for r in runs]
    worst = max(abs(x - 1.0) for x in ratios)
    verdict = "met" if worst <= 0.05 else "not met"
    return (
        f"ratios {min(ratios):.3f}–{max(ratios):.3f}, the farthest {100 * worst:.1f} % from the "
        f"task level (target within 5 %: {verdict})"
    )


def report(runs: list[dict], args, wall: float) -> str:
    """The report's Markdown."""
    from importlib.metadata import version

    settings = "lean (0.5 s holds)" if args.lean else "full (5 s holds, TCP <= 0.25 m/s)"
    errors = [
        f"- {r['cell']}, {r['interface']}, {r['mode']}: {r['error']}" for r in runs if r["error"]
    ]
    return "\n".join(
        [
            "# The cell anticipating against the cell waiting",
            "",
            f"`python benchmarks/bench_anticipation_cell.py --workers {args.workers}"
            f"{' --lean' if args.lean else ''}` — drake {version('drake')}, "
            f"{platform.machine()}, {multiprocessing.cpu_count()} cores, Python "
            f"{platform.python_version()}; {len(runs)} runs in {wall / 60:.1f} min of wall time. "
            f"Settings: {settings}; the operator's body and the separation monitor on.",
            "",
            "*delay*: the seconds `wait` spends from each prompt to its indication (the "
            "interface's delay, the same draws in both modes); *saved*: T_wait − T_anticipate; "
            "*share*: saved / delay. Row 8's operator mounts F3 where the robot proposed F1: the "
            "robot, already lifting the flange, re-targets. *states of react*: both modes visit "
            "the states the task layer's decision loop gives for the scenario's policy and "
            "operator. *task*: the same run at task level "
            "from the cell's cost table (the same operator and delay draws); *cell / task*: "
            "their ratio (target within 5 %).",
            "",
            "| cell | interface | anticipate [s] | task [s] | cell / task | wait [s] | task [s] | "
            "cell / task | delay [s] | saved [s] | share | re-targets | swaps | states of react | "
            "terminal | collisions | violations | drops |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
            *rows(runs),
            "",
            f"Cell against task level: {agreement(runs)}.",
            "",
            *(["Errors:", "", *errors, ""] if errors else []),
        ]
    )


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true", help="0.5 s holds: a quick look")
    args = parser.parse_args(argv)
    jobs = [(c, i, m, args.lean) for c in CELLS for i in interfaces(c) for m in MODES]
    runs, wall = run_pool(one_run, jobs, args.workers)
    add_task_level(runs, jobs)
    publish(report(runs, args, wall), REPORT, args.lean)
    return 0


if __name__ == "__main__":
    sys.exit(main())
