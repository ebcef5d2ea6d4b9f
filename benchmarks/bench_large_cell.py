"""Larger assemblies through the cell: the shipped gearbox cover (six parts, two host parts) and
two more specs of six and seven parts, each run by the commands a user types.

Run on demand (not part of pytest):

    python benchmarks/bench_large_cell.py [--only full,simulate,evaluate] [--specs NAME,...]

1. `full`: the shipped case at full settings (5 s bolting holds), `hrc-drake simulate --scenario
   gearbox-cover --json`: per task its proposal, what the cell observed, its simulated time, how
   long the arm waited for the planner (`idle_time`, simulated; `wall_idle_time`, wall clock)
   and whether its plan was ready (planned ahead while the operator bolted); the run's
   simulated and wall time and real-time factor. Then the planning time per task: each task of
   the run's route planned by a fresh `MotionPlanner` on the same cell and motion options (the
   planning worker's work, cold), and the check before a run (room and reach) timed.
2. `simulate`: each spec lean, with no deviation and with two operator scripts
   (`--operator "STEP:TOKEN,..."`: overrides the robot then undoes, and where the spec has
   mistakes a part in a wrong seat): terminal or not, collisions, tasks, simulated and wall
   time (the process's, start-up included).
3. `evaluate`: `hrc-drake evaluate --cell --assembly SPEC --decider exact --operator-model
   random --runs 6 --lean --json`: runs completed, capped, collisions, failures, wall time (the
   first time for a spec and layout this includes planning its cost table, then cached).

Results are kept per item in benchmarks/reports/large_cell.json, so that `--only` re-runs a part;
the report benchmarks/reports/large_cell.md is rebuilt from all of them (atomically).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from hrc_drake.atomic import atomic_write_text

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
RESULTS = HERE / "reports" / "large_cell.json"
REPORT = HERE / "reports" / "large_cell.md"
HRC = str(Path(sys.executable).parent / "hrc-drake")
# Spec -> (path, two operator scripts: overrides, then a misplacement where the spec has them).
SPECS = {
    "gearbox-cover": ("models/assemblies/gearbox-cover.yaml", ("1:A23,3:B56", "2:E02,4:E16")),
    "valve-manifold": ("benchmarks/specs/valve-manifold.yaml", ("1:P23", "2:V02,4:Q56")),
    "pump-bracket": ("benchmarks/specs/pump-bracket.yaml", ("1:M234", "2:T02,4:T14")),
}


def _run(argv: list[str]) -> tuple[int, str, str, float]:
    """Run a command from the repository; (exit status, stdout, stderr, wall seconds)."""
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, env=os.environ.copy())
    return done.returncode, done.stdout, done.stderr, time.perf_counter() - start


def _command(argv: list[str]) -> str:
    return " ".join(["hrc-drake", *(f'"{a}"' if "," in a or " " in a else a for a in argv[1:])])


def _full() -> dict:
    """The shipped case at full settings, and its planning time per task."""
    argv = [HRC, "simulate", "--scenario", "gearbox-cover", "--json"]
    code, out, err, wall = _run(argv)
    if code != 0:
        return {"command": _command(argv), "error": err.strip()[-400:]}
    run = json.loads(out)
    return {
        "command": _command(argv),
        "process_wall": round(wall, 1),
        "run": {k: run[k] for k in ("terminal", "collisions", "names", "sim_time", "wall_time")}
        | {"real_time_factor": run["real_time_factor"], "steps": run["steps"]},
        "planning": _planning(run["states"]),
    }


def _planning(states: list[list[str]]) -> dict:
    """Each task of the route planned by a fresh planner (cold), and the check before a run."""
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.motion.planner import MotionPlanner
    from hrc_drake.motion.reach_check import check_reach, check_room
    from hrc_drake.tasks.spec import load_spec

    scenario = load_cell_scenario("gearbox-cover", [])
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    start = time.perf_counter()
    planner = MotionPlanner(motion_options(scenario), design=design)
    build = time.perf_counter() - start
    start = time.perf_counter()
    check_room(planner, suggest=False)
    room = time.perf_counter() - start
    start = time.perf_counter()
    check_reach(planner, suggest=False)
    whole = time.perf_counter() - start
    tasks = []
    for before, after in itertools.pairwise(states):
        task = after[-1] if len(after) > len(before) else "undo"
        start = time.perf_counter()
        planner.plan_task(set(before), task, last_token=before[-1] if before else None)
        tasks.append([task, round(time.perf_counter() - start, 2)])
    return {"planner": round(build, 2), "room": round(room, 3), "check": round(whole, 2),
            "tasks": tasks}  # fmt: skip


def _simulate(name: str) -> list[dict]:
    path, scripts = SPECS[name]
    out = []
    for script in ("", *scripts):
        argv = [HRC, "simulate", "--assembly", path, "--lean", "--json"]
        if script:
            argv += ["--operator", script]
        code, stdout, err, wall = _run(argv)
        item = {"command": _command(argv), "process_wall": round(wall, 1), "status": code}
        if code == 0:
            run = json.loads(stdout)
            item |= {
                "terminal": run["terminal"],
                "final_kind": run["final_kind"],
                "collisions": run["collisions"],
                "tasks": len(run["steps"]),
                "handovers": [
                    f"{step['observed']}: {step['handover_reason']}"
                    for step in run["steps"]
                    if step.get("handed_over")
                ],
                "names": run["names"],
                "sim_time": run["sim_time"],
                "wall_time": run["wall_time"],
            }
        else:
            item["error"] = err.strip()[-400:]
        print(f"{name} {script or 'no deviation'}: {item.get('final_kind', 'error')}", flush=True)
        out.append(item)
    return out


def _evaluate(name: str) -> dict:
    path, _ = SPECS[name]
    argv = [HRC, "evaluate", "--cell", "--assembly", path, "--decider", "exact",
            "--operator-model", "random", "--runs", "6", "--lean", "--json"]  # fmt: skip
    code, stdout, err, wall = _run(argv)
    item = {"command": _command(argv), "process_wall": round(wall, 1), "status": code}
    if code == 0:
        report = json.loads(stdout)
        keep = ("runs", "completed", "capped", "collisions", "failures", "mean_tasks")
        item |= {k: report.get(k) for k in keep}
    else:
        item["error"] = err.strip()[-400:]
    return item


def _steps_table(full: dict) -> list[str]:
    run, planning = full["run"], full["planning"]
    plan = dict(planning["tasks"]) if len(planning["tasks"]) == len(run["steps"]) else {}
    lines = [
        "| step | proposed | observed | task [s, simulated] | planning [s] | arm idle [s] | "
        "arm idle [s, wall] | plan ready |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for step in run["steps"]:
        lines.append(
            f"| {step['step']} | {step['proposed']} | {step['observed']} | {step['sim_time']:.2f} "
            f"| {plan.get(step['observed'], float('nan')):.2f} | {step['idle_time']:.2f} | "
            f"{step['wall_idle_time']:.2f} | {'yes' if step['plan_ready'] else 'no'} |"
        )
    return lines


def _section(title: str, columns: tuple[str, ...], rows: list[str]) -> list[str]:
    """A report section: its title and a table of `rows` under `columns` (none: no section)."""
    if not rows:
        return []
    header = f"| {' | '.join(columns)} |"
    return [f"## {title}", "", header, "|" + "---|" * len(columns), *rows, ""]


def _report(results: dict) -> str:
    lines = [
        "# Larger assemblies through the cell",
        "",
        "`python benchmarks/bench_large_cell.py` (module docstring: what each part runs). The "
        "shipped case `gearbox-cover` (models/assemblies/gearbox-cover.yaml: six parts, two "
        "host parts, 331 states) and two specs of our own (benchmarks/specs/: "
        "`valve-manifold`, seven parts, 242 states; `pump-bracket`, six parts, 493 states), "
        "each in the layout of its `cell:` section.",
        "",
    ]
    full = results.get("full")
    if full:
        lines += ["## The shipped case at full settings", "", f"`{full['command']}`", ""]
        if "error" in full:
            lines += [f"Failed: {full['error']}", ""]
        else:
            run, planning = full["run"], full["planning"]
            lines += [
                f"Terminal: {run['terminal']}, collisions: {run['collisions']}, states "
                f"{' '.join(run['names'])}; {run['sim_time']:.1f} s simulated in "
                f"{run['wall_time']:.1f} s wall: real-time factor {run['real_time_factor']:.2f} "
                f"(planning included; the process took {full['process_wall']:.0f} s with "
                "start-up).",
                "",
                *_steps_table(full),
                "",
                f"Planning per task (a fresh planner, cold, on this machine; the run plans the "
                f"same in its worker while the operator bolts): "
                f"{', '.join(f'{t} {s:.2f} s' for t, s in planning['tasks'])}. Building the "
                f"planner {planning['planner']:.2f} s; the check before a run "
                f"{planning['check']:.2f} s, of which the occupancy rule {planning['room']:.3f} s.",
                "",
            ]
    rows = []
    for name in SPECS:
        for item in results.get("simulate", {}).get(name, []):
            outcome = (
                f"{item['final_kind']}, {item['collisions']} collisions, {item['tasks']} tasks"
                f"{'; handed over: ' + ' / '.join(item['handovers']) if item['handovers'] else ''} "
                f"| {item['sim_time']:.1f} | {item['wall_time']:.1f} | {item['process_wall']:.0f}"
                if item["status"] == 0
                else f"error: {item['error']} | | |"
            )
            rows.append(f"| `{item['command']}` | {outcome} |")
    lines += _section(
        "simulate, lean, with and without deviations",
        ("command", "outcome", "simulated [s]", "run wall [s]", "process wall [s]"),
        rows,
    )
    rows = []
    for name in SPECS:
        item = results.get("evaluate", {}).get(name)
        if item is None:
            continue
        outcome = (
            f"{item['runs']} runs: {item['completed']} terminal, {item['capped']} capped, "
            f"{item['collisions']} collisions, failures {item['failures'] or 'none'}, "
            f"{item['mean_tasks']} tasks a run"
            if item["status"] == 0
            else f"error: {item['error']}"
        )
        rows.append(f"| `{item['command']}` | {outcome} | {item['process_wall']:.0f} |")
    lines += _section(
        "evaluate --cell, random operator, lean", ("command", "outcome", "wall [s]"), rows
    )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", default="full,simulate,evaluate", help="comma-separated")
    parser.add_argument("--specs", default=",".join(SPECS), help="comma-separated")
    args = parser.parse_args()
    parts, names = args.only.split(","), args.specs.split(",")
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}

    def save() -> None:
        atomic_write_text(RESULTS, json.dumps(results, indent=1) + "\n")
        atomic_write_text(REPORT, _report(results))

    if "full" in parts:
        results["full"] = _full()
        save()
    for name in names:
        if "simulate" in parts:
            results.setdefault("simulate", {})[name] = _simulate(name)
            save()
        if "evaluate" in parts:
            results.setdefault("evaluate", {})[name] = _evaluate(name)
            save()
    print(_report(results))


if __name__ == "__main__":
    main()
