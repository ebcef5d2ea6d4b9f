"""Robust to contact settings: the guarded descent against the hydroelastic modulus, and the
in-hand creep against the time step -> benchmarks/reports/contact_robustness.md.

1. **The guarded descent.** The `no-seat` fault (the part slides 8–12 mm in the fingers, so the
   robot lowers it onto a pocket's rim) on the flange case (row 1) and the 4-slot cell, the
   seeds of `bench_faults.py` (the same task struck, the same offset), at the scenario's
   5e6 Pa and at Drake's default 1e7 Pa with the guarded descent (`run.place_guard`, 8 N),
   and at 1e7 Pa without it (`run.place_guard: 0`, the arm presses on to the plan's place);
   beside them row 1 with no fault at both moduli. Per setting: runs, detected, recovered
   (re-placed and the assembly finished), the guard's trips and the load and height it tripped
   at, runs stopped, collisions.
2. **In-hand creep.** The square flange (0.57 kg) held at the end of its lift by the pads'
   friction alone (20 N), carried along row 1's plan to its pre-place pose and then held still
   for `HOLD` s, at 10 ms and 5 ms plant steps (and both moduli): how far it slides in the
   fingers, along the approach (out of the grasp) and along the part, and how fast.

Usage: ``python benchmarks/bench_contact_robustness.py [--seeds 3] [--workers 2] [--lean]
[--creep-only]`` (full settings by default: 5 s holds; ``--lean`` prints the report instead of
writing it; ``--creep-only`` measures the creep again and rewrites that section of the report).
"""

from __future__ import annotations

import argparse
import multiprocessing
import platform
import re
import sys
from pathlib import Path

import numpy as np
from bench_faults import _texts, fault_entry, modulus_text, one_run, run_tasks
from cell_pool import pooled_loop, publish, run_pool

from hrc_drake.hri.faults import FaultKind

REPORT = Path(__file__).parent / "reports" / "contact_robustness.md"
CELLS = ("flange", "four-slot")
NO_SEAT = FaultKind.NO_SEAT.value
# (name, modulus [Pa], guarded)
SETTINGS = (
    ("5e6 Pa, guarded", 5.0e6, True),
    ("1e7 Pa, guarded", 1.0e7, True),
    ("1e7 Pa, unguarded", 1.0e7, False),
)
NORMAL_MODULI = (5.0e6, 1.0e7)
GUARD_EVENT = re.compile(r"meets something ([\d.]+) mm above its place \((\d+) N")
HOLD = 2.0  # s, the creep's still hold after the carry


def _extra(modulus: float, guarded: bool) -> tuple[str, ...]:
    return (modulus_text(modulus),) + (() if guarded else ("{run: {place_guard: 0}}",))


def fault_jobs(seeds: int, lean: bool) -> list[tuple]:
    """The no-seat runs: every cell x seed x setting (bench_faults' jobs, its entries)."""
    jobs = []
    for cell in CELLS:
        tasks = run_tasks(cell, lean)
        for seed in range(seeds):
            entry = fault_entry(NO_SEAT, seed, tasks)
            for name, modulus, guarded in SETTINGS:
                jobs.append((cell, NO_SEAT, seed, entry, lean, _extra(modulus, guarded), name))
    return jobs


def fault_run(job: tuple) -> dict:
    """One no-seat run (`bench_faults.one_run`), with its setting's name and the guard's
    trips read from its events."""
    *head, name = job
    run = one_run(tuple(head))
    found = (GUARD_EVENT.search(e) for e in run["events"])
    trips = [tuple(float(x) for x in m.groups()) for m in found if m]
    return {**run, "setting": name, "trips": trips}


def normal_run(job: tuple[float, bool]) -> dict:
    """Row 1 with no fault at `modulus` (guarded): terminal, its states, time, collisions."""
    from hrc_drake.cell.scenario import load_cell_scenario

    modulus, lean = job
    texts = [*_texts("flange", lean), modulus_text(modulus)]
    result = pooled_loop(load_cell_scenario("row1-optimal", texts), "flange").run()
    return {
        "modulus": modulus,
        "done": result.done,
        "states": [list(s) for s in result.states],
        "sim_time": result.sim_time,
        "collisions": len(result.collisions),
        "trips": sum(bool(GUARD_EVENT.search(e)) for e in result.events),
        "error": result.error,
    }


def dispatch(job: tuple) -> dict:
    """A pool's job: a no-seat run or a normal one."""
    return normal_run(job) if len(job) == 2 else fault_run(job)


def _fmt_trips(runs: list[dict]) -> str:
    trips = [t for r in runs for t in r["trips"]]
    if not trips:
        return "0"
    heights = [t[0] for t in trips]
    loads = [t[1] for t in trips]
    return (
        f"{len(trips)} ({min(heights):.1f}–{max(heights):.1f} mm above, "
        f"{min(loads):.0f}–{max(loads):.0f} N)"
    )


def fault_rows(runs: list[dict]) -> list[str]:
    """The no-seat summary table's rows, one per cell and setting."""
    rows = []
    for cell in CELLS:
        for name, _, _ in SETTINGS:
            mine = [r for r in runs if r["cell"] == cell and r["setting"] == name]
            detected = [r for r in mine if r["record"]["detected_at"] is not None]
            recovered = [r for r in detected if r["record"]["recovered"] and r["terminal"]]
            stopped = [r for r in mine if not r["terminal"]]
            lost = [r["record"]["seconds_lost"] for r in detected if r["record"]["recovered"]]
            rows.append(
                f"| {cell} | {name} | {len(mine)} | {len(detected)}/{len(mine)} | "
                f"{len(recovered)}/{len(mine)} | {_fmt_trips(mine)} | {len(stopped)} | "
                f"{np.mean(lost) if lost else 0:.2f} | {sum(r['collisions'] for r in mine)} |"
            )
    return rows


def run_rows(runs: list[dict]) -> list[str]:
    """One row per no-seat run."""
    rows = []
    for r in runs:
        end = (
            "done"
            if r["terminal"]
            else next(
                (e.split("stopped: ", 1)[1] for e in r["events"] if "stopped: " in e), "stopped"
            )
        )
        trips = "; ".join(f"{h:.1f} mm, {n:.0f} N" for h, n in r["trips"]) or "—"
        rows.append(
            f"| {r['cell']} | {r['seed']} | `{r['entry']}` | {r['setting']} | "
            f"{r['record']['recovery'] or '—'} | {trips} | {end[:110]} |"
        )
    return rows


def normal_rows(runs: list[dict]) -> list[str]:
    """Row 1 with no fault, one row per modulus."""
    return [
        f"| {r['modulus']:g} | {'yes' if r['done'] else 'no'} | "
        f"{' → '.join(' '.join(s) or '()' for s in r['states'])} | {r['sim_time']:.2f} | "
        f"{r['trips']} | {r['collisions']} |"
        for r in runs
    ]


CREEP_SETTINGS = ((0.01, 5.0e6), (0.005, 5.0e6), (0.01, 1.0e7), (0.005, 1.0e7))  # (s, Pa)


def creep(time_step: float, modulus: float, hold: float) -> dict:
    """The square flange held at the end of its lift, carried along row 1's S23 plan to the
    pre-place pose, then held still `hold` s, at `time_step` and `modulus`: its slide in the
    fingers [m] over the carry and over the hold, in the tcp frame (z: the approach, out of
    the grasp; x: along the part), and the carry's length [s]."""
    from pydrake.systems.analysis import Simulator

    from hrc_drake.cell.run.run import shared_planner
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.cell.station import make_cell_station
    from hrc_drake.motion.plan import LIFT, Stage
    from hrc_drake.robot_models import set_rg2_opening
    from hrc_drake.robot_names import GRIPPER, UR3
    from hrc_drake.tasks.spec import load_spec

    text = (
        f"{{plant_config: {{time_step: {time_step}}}, scene_graph_config: "
        f"{{default_proximity_properties: {{hydroelastic_modulus: {modulus:g}}}}}, "
        "body: {enabled: false}}"
    )
    scenario = load_cell_scenario(None, text)
    station, part = make_cell_station(scenario), "square_flange"
    plant, diagram = station.plant, station.diagram
    options = motion_options(scenario)
    plan = shared_planner(options, cell_design(scenario, load_spec(scenario.assembly_path)))
    plan = plan.plan_task(frozenset(), "S23")
    lift = next(m for m in plan.motions if m.name == LIFT)
    t0, t1 = lift.start + lift.duration, plan.segment(Stage.CARRY).end
    context = station.create_default_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    width = float(station.frames.widths[part])
    plant.SetPositions(plant_context, station.instances[UR3], plan.positions(t0))
    set_rg2_opening(plant, plant_context, width, station.instances[GRIPPER])
    tcp = plant.GetFrameByName("tcp", station.instances[GRIPPER])
    X_W_part = tcp.CalcPoseInWorld(plant_context) @ station.frames.grasps[part].inverse()
    plant.SetFreeBodyPose(plant_context, station.part_body(part), X_W_part)
    station.hold_robot(context, opening=width - options.grip_squeeze)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(0.3)  # the fingers stall on the part

    def in_hand() -> np.ndarray:
        X = tcp.CalcPoseInWorld(plant_context).InvertAndCompose(
            plant.EvalBodyPoseInWorld(plant_context, station.part_body(part))
        )
        return X.translation()

    root = diagram.GetMyMutableContextFromRoot(context)
    start, begin = in_hand(), context.get_time()
    for tau in np.arange(t0, t1 + 1e-9, time_step):
        v = plan.trajectory.EvalDerivative(tau, 1).ravel()
        diagram.GetInputPort("ur3.position").FixValue(root, plan.positions(tau))
        diagram.GetInputPort("ur3.velocity").FixValue(root, v)
        simulator.AdvanceTo(begin + (tau - t0) + time_step)
    carried = in_hand()
    diagram.GetInputPort("ur3.velocity").FixValue(root, np.zeros(6))
    simulator.AdvanceTo(context.get_time() + hold)
    return {"carry": carried - start, "hold": in_hand() - carried, "carry_time": t1 - t0}


def creep_rows(hold: float) -> list[str]:
    """Experiment 2's section of the report."""
    lines = [
        "## 2. In-hand creep",
        "",
        f"The square flange (0.57 kg) held by the pads' friction alone (20 N), carried along "
        f"row 1's S23 plan from the end of its lift to the pre-place pose, then held still "
        f"{hold:g} s. Its slide in the fingers, in the tcp frame: *down* along the approach "
        "(out of the grasp, the way its weight pulls), *along* the part (the pads' long "
        "direction), *across* the pads (toward a finger); *along, per s*: the slide along the "
        "part over the carry's time.",
        "",
        "| time step [ms] | modulus [Pa] | carry [s] | carry: down, along, across [mm] | "
        "along, per s [mm/s] | hold: down, along, across [mm] | hold, per s [mm/s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for time_step, modulus in CREEP_SETTINGS:
        c = creep(time_step, modulus, hold)
        along = abs(float(c["carry"][0])) / c["carry_time"] * 1000
        rate = float(np.linalg.norm(c["hold"])) / hold * 1000
        carried, held = (
            ", ".join(f"{c[k][i] * 1000:.2f}" for i in (2, 0, 1)) for k in ("carry", "hold")
        )
        lines.append(
            f"| {time_step * 1000:g} | {modulus:g} | {c['carry_time']:.2f} | {carried} | "
            f"{along:.2f} | {held} | {rate:.2f} |"
        )
        print(lines[-1], flush=True)
    return [*lines, ""]


def main(argv: list[str] | None = None) -> int:
    """Run the two experiments and write (or, lean, print) the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true", help="0.5 s holds: a quick look")
    parser.add_argument("--creep-only", action="store_true", help="only the in-hand creep")
    args = parser.parse_args(argv)
    runs, normals, wall = [], [], 0.0
    if not args.creep_only:
        jobs = [*fault_jobs(args.seeds, args.lean), *((m, args.lean) for m in NORMAL_MODULI)]
        done, wall = run_pool(dispatch, jobs, args.workers)
        runs = [r for r in done if "setting" in r]
        normals = [r for r in done if "setting" not in r]
    creeps = creep_rows(HOLD)
    if args.creep_only:
        update_creep(creeps)
        return 0
    publish(report(args, runs, normals, creeps, wall), REPORT, args.lean)
    return 0


def update_creep(creeps: list[str]) -> None:
    """`--creep-only`: the report's section 2 measured again, the rest as it stands (printed
    if there is no report yet)."""
    from hrc_drake.atomic import atomic_write_text

    text = "\n".join(creeps)
    if not REPORT.exists():
        print(text)
        return
    old = REPORT.read_text()
    head, rest = old.split("## 2. In-hand creep", 1)
    tail = rest[rest.index("## Runs") :]
    atomic_write_text(REPORT, head + text + tail)
    print(f"{text}\nsection 2 of {REPORT} measured again")


def report(args, runs, normals, creeps, wall: float) -> str:
    """The report's Markdown."""
    from importlib.metadata import version

    settings = "lean (0.5 s holds)" if args.lean else "full (5 s holds, TCP <= 0.25 m/s)"
    lines = [
        "# Robust to contact settings: the guarded descent, the in-hand creep",
        "",
        f"`python benchmarks/bench_contact_robustness.py --seeds {args.seeds} --workers "
        f"{args.workers}{' --lean' if args.lean else ''}` — drake {version('drake')}, "
        f"{platform.machine()}, {multiprocessing.cpu_count()} cores (shared with other work "
        f"while it ran), Python {platform.python_version()}; {len(runs) + len(normals)} runs "
        f"in {wall / 60:.1f} min of wall time. Settings: {settings}, seeds 0–{args.seeds - 1}.",
        "",
        "## 1. The no-seat fault against the hydroelastic modulus",
        "",
        "The part slides 8–12 mm along the pads in the carry (seeded as in `bench_faults.py`: "
        "the same task struck, the same offset), so the robot lowers it onto its pocket's "
        "rim. *guarded*: the guarded descent on (`run.place_guard: 8`, the default); "
        "*unguarded*: `run.place_guard: 0`, the arm presses on to the plan's place. "
        "*recovered*: detected, re-placed, and the assembly finished; *guard trips*: how "
        "often the guard stopped a descent, how far above its place the tool then was and "
        "the rise of the load against the approach it read; *stopped*: runs that ended "
        "before the assembly did; *lost*: mean simulated seconds from the injection to the "
        "recovery.",
        "",
        "| cell | setting | runs | detected | recovered | guard trips | stopped | lost, mean [s] "
        "| collisions |",
        "|---|---|---|---|---|---|---|---|---|",
        *fault_rows(runs),
        "",
        "Row 1 with no fault (the guarded descent on):",
        "",
        "| modulus [Pa] | terminal | states | sim time [s] | guard trips | collisions |",
        "|---|---|---|---|---|---|",
        *normal_rows(normals),
        "",
        *creeps,
        "## Runs",
        "",
        "| cell | seed | fault | setting | recovery | guard trips | end |",
        "|---|---|---|---|---|---|---|",
        *run_rows(runs),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
