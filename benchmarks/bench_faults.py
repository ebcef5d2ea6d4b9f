"""Faults injected into the cell, found and survived -> benchmarks/reports/faults.md.

Every fault kind the cell simulates x `--seeds` seeds (default 10), on the flange case and on
the 4-slot cell, full settings (5 s bolting holds, TCP <= 0.25 m/s; `--lean` for a quick look),
the operator's body and the separation monitor on. A seed draws the task the fault strikes (any
task of the run), when it strikes, and the kind's other parameter (a stop's length, how long
the operator stays silent, whether the gripper sticks closed or open). Per cell and kind:
detection rate (of the faults injected, those the controller found from its measurements),
recovery rate (the cell went on by itself and finished the assembly), the simulated time lost,
robot collisions, separation violations (the robot moving under its own command closer than
S_p) and, apart, the steps an outside force (a push) moved the arm closer than S_p.

Usage: ``python benchmarks/bench_faults.py [--seeds 10] [--workers 2] [--lean] [--modulus PA]
[--camera] [--kinds no-seat,...]`` (with ``--lean`` the report is printed, not written; with
``--modulus`` the parts' hydroelastic modulus is that instead of the scenario's 5e6 Pa and the
report is written to ``faults_E<PA>.md``; with ``--camera`` every measured port is read through
the `realistic` sensor models and the parts' verdicts come from the camera
(`{sensors: {preset: realistic, configuration: camera}}`), the camera's false and missed
detections and wrong-slot verdicts against the contact sensor are counted, and the report is
written to ``faults_camera.md``; ``--kinds`` runs only those cases).
"""

from __future__ import annotations

import argparse
import multiprocessing
import platform
import sys
from pathlib import Path

import numpy as np
from cell_pool import CAMERA_TEXT, pooled_loop, run_pool

from hrc_drake.atomic import atomic_write_text
from hrc_drake.hri.faults import FAULT_CLASSES, SIMULATED, FaultKind

CELLS = {"flange": "row1-optimal", "four-slot": None}
# What the cell should do with each kind: recover and go on, or hand the task over.
RECOVERS = {
    FaultKind.PROTECTIVE_STOP: True,
    FaultKind.OPERATOR_SILENT: True,
    FaultKind.PUSHED: False,
    FaultKind.GRIPPER_STUCK: False,
    FaultKind.GRIP_LOST: True,
    FaultKind.NO_SEAT: True,
    FaultKind.NO_PATH: True,
}
# The cases run: each kind, and no-seat with debris in the pocket, which no re-placement
# fixes (the cell should hand it over).
NO_SEAT_DEBRIS = "no-seat (debris)"
CASES = [*(k.value for k in SIMULATED), NO_SEAT_DEBRIS]


def case_kind(case: str) -> FaultKind:
    """The fault kind of a case."""
    return FaultKind.NO_SEAT if case == NO_SEAT_DEBRIS else FaultKind(case)


def should_recover(case: str) -> bool:
    """Whether the cell should recover from a case by itself."""
    return case != NO_SEAT_DEBRIS and RECOVERS[FaultKind(case)]


REPORT = Path(__file__).parent / "reports" / "faults.md"


def fault_entry(case: str, seed: int, tasks: int) -> str:
    """The `faults:` entry of one seeded run (YAML flow text, tagged: `!GripLost {...}`)."""
    kind = case_kind(case)
    rng = np.random.default_rng([seed, CASES.index(case)])
    task = int(rng.integers(1, tasks + 1))
    extra = {
        FaultKind.PROTECTIVE_STOP: f"after: {rng.uniform(3.0, 6.0):.2f}, "
        f"duration: {rng.uniform(0.5, 3.0):.2f}",
        FaultKind.OPERATOR_SILENT: f"duration: {rng.uniform(11.0, 20.0):.2f}",
        FaultKind.PUSHED: f"after: {rng.uniform(3.0, 6.0):.2f}",
        FaultKind.GRIPPER_STUCK: f"stuck: {'close' if seed % 2 == 0 else 'open'}",
        FaultKind.GRIP_LOST: f"after: {rng.uniform(0.3, 1.5):.2f}",
        FaultKind.NO_SEAT: f"offset: {rng.uniform(0.008, 0.012):.4f}",
        FaultKind.NO_PATH: f"duration: {rng.uniform(4.0, 9.0):.2f}",
    }[kind]
    if case == NO_SEAT_DEBRIS:
        extra = "obstacle: true"
    return f"!{FAULT_CLASSES[kind].__name__} {{task: {task}, {extra}}}"


def _texts(cell: str, lean: bool) -> list[str]:
    texts = [] if CELLS[cell] else [f"{{assembly: {cell}, name: {cell}}}"]
    if lean:
        from hrc_drake.cell.scenario import LEAN

        texts.append(LEAN)
    return texts


def run_tasks(cell: str, lean: bool) -> int:
    """How many tasks the cell's run has (its operator follows the robot)."""
    from hrc_drake.cell.run.run import scenario_policy
    from hrc_drake.cell.scenario import load_cell_scenario
    from hrc_drake.hri.operator import ScriptedOperator
    from hrc_drake.tasks.decide import run_decisions
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    scenario = load_cell_scenario(CELLS[cell], _texts(cell, lean))
    space = generate_states(load_spec(scenario.assembly_path))
    _, decisions = run_decisions(space, scenario_policy(scenario, space), ScriptedOperator({}))
    return len(decisions)


def modulus_text(modulus: float) -> str:
    """The scenario text that sets the parts' hydroelastic modulus [Pa]."""
    return (
        "{scene_graph_config: {default_proximity_properties: "
        f"{{hydroelastic_modulus: {modulus:g}}}}}}}"
    )


def one_run(job: tuple) -> dict:
    """One faulted run (`job`: cell, case, seed, fault entry, lean, and optionally more
    scenario texts); its fault record and the run's figures."""
    from hrc_drake.cell.scenario import load_cell_scenario

    cell, kind, seed, entry, lean, *extra = job
    texts = [*_texts(cell, lean), *(extra[0] if extra else ()), f"{{faults: [{entry}]}}"]
    try:
        result = pooled_loop(load_cell_scenario(CELLS[cell], texts), cell).run()
    except RuntimeError as err:
        # The simulation itself failed (Drake's error, e.g. a pose gone NaN): a finding of
        # the run, reported, not the end of the benchmark.
        return crashed_run(cell, kind, seed, entry, err)
    (record,) = result.faults
    safety = result.safety
    return {
        "cell": cell,
        "kind": kind,
        "seed": seed,
        "entry": entry,
        "record": record.to_json(),
        "terminal": result.done,
        "collisions": len(result.collisions),
        "violations": safety.violations if safety is not None else 0,
        "imposed": safety.imposed if safety is not None else 0,
        "sim_time": result.sim_time,
        # A task handed over no longer ends the run: its reason is the step's.
        "out_of_reach": out_of_reach(
            result.error or next((t.handed_over for t in result.tasks if t.handed_over), None)
        ),
        "handovers": result.handovers,
        "events": list(result.events),
        "camera": result.camera,
    }


def crashed_run(cell: str, kind: str, seed: int, entry: str, err: Exception) -> dict:
    """The figures of a run whose simulation failed: nothing detected or recovered, and the
    error's first line."""
    record = {"injected_at": None, "detected_at": None, "recovered": False, "recovery": None}
    return {
        "cell": cell,
        "kind": kind,
        "seed": seed,
        "entry": entry,
        "record": {**record, "seconds_lost": 0.0},
        "terminal": False,
        "collisions": 0,
        "violations": 0,
        "imposed": 0,
        "sim_time": float("nan"),
        "out_of_reach": False,
        "handovers": 0,
        "events": [],
        "camera": None,
        "crashed": str(err).strip().splitlines()[0],
    }


def crash_note(runs: list[dict]) -> list[str]:
    """A line per run whose simulation failed (none: nothing)."""
    crashed = [r for r in runs if r.get("crashed")]
    if not crashed:
        return []
    lines = [f"{len(crashed)} run(s) failed in the simulation itself (counted as not injected):"]
    lines += [f"- {r['cell']} seed {r['seed']} `{r['entry']}`: {r['crashed']}" for r in crashed]
    return [*lines, ""]


def out_of_reach(error: str | None) -> bool:
    """Whether a run ended because its part came to rest where the robot has no grasp of it
    (the planner's verdict on the measured pose: tilted past what a grasp from above allows,
    or the fingers would touch what it lies on); the cell should hand such a part over."""
    return bool(error) and "from where it lies" in error and "pose is unreachable" in error


def summary_rows(runs: list[dict]) -> list[str]:
    """The report's table rows, one per cell and kind."""
    rows = []
    for cell in CELLS:
        for case in CASES:
            mine = [r for r in runs if r["cell"] == cell and r["kind"] == case]
            if not mine:
                continue  # a case not run (`--kinds`)
            injected = [r for r in mine if r["record"]["injected_at"] is not None]
            detected = [r for r in injected if r["record"]["detected_at"] is not None]
            recovered = [r for r in detected if r["record"]["recovered"] and r["terminal"]]
            reachable = [r for r in detected if not r.get("out_of_reach")]
            lost = [r["record"]["seconds_lost"] for r in detected]
            expected = "recover" if should_recover(case) else "hand over"
            rows.append(
                f"| {cell} | {case} | {expected} | {len(mine)} | {len(injected)} | "
                f"{len(detected)}/{len(injected)} | {len(detected) - len(reachable)} | "
                f"{len(recovered)}/{len(reachable)} | "
                f"{np.mean(lost) if lost else 0:.2f} | {max(lost) if lost else 0:.2f} | "
                f"{sum(r['collisions'] for r in mine)} | {sum(r['violations'] for r in mine)} | "
                f"{sum(r['imposed'] for r in mine)} |{camera_cells(mine)}"
            )
    return rows


def camera_cells(runs: list[dict]) -> str:
    """The camera's columns of a row: false and missed detections and wrong-slot verdicts
    against the contact sensor, summed over `runs` (empty without the camera)."""
    scores = [r["camera"] for r in runs if r.get("camera")]
    if not scores:
        return ""
    keys = ("false_detections", "missed_detections", "wrong_slot")
    return "".join(f" {sum(c[k] for c in scores)} |" for k in keys)


def camera_note(runs: list[dict]) -> list[str]:
    """With the camera: what its columns count, and each false or missed detection."""
    events = [
        f"- {r['cell']} seed {r['seed']} `{r['entry']}`: {event}"
        for r in runs
        if r.get("camera")
        for event in r["camera"]["events"]
    ]
    if not any(r.get("camera") for r in runs):
        return []
    return [
        "*camera*: the camera's `seated` and `misplaced` verdicts scored against the contact "
        "sensor's, the simulator's ground truth (`configuration.camera` of a run's JSON; "
        "`hrc_drake/cell/station/camera_score.py`): *false*, a verdict the truth never showed; "
        "*missed*, a verdict of the truth the camera never reported; *wrong slot*, a false "
        "`seated` while the part sat in another seat.",
        "",
        *(events or ["The camera made no false or missed detection."]),
        "",
    ]


def violations_note(runs: list[dict]) -> list[str]:
    """A paragraph on the kinds whose runs counted separation violations, if any, and on the
    steps pushed closer than S_p while the robot held still."""
    kinds = sorted({r["kind"] for r in runs if r["violations"]})
    text = (
        f"Separation violations (monitor steps with the arm moving closer to the body than S_p "
        f"under its own command) were counted only in {', '.join(kinds)} runs."
        if kinds
        else "No run counted a separation violation."
    )
    pushed = sorted({r["kind"] for r in runs if r["imposed"]})
    if pushed:
        text += (
            f" *Moved from outside* counts, apart, the steps of {', '.join(pushed)} runs in "
            "which the arm came closer than S_p while an outside force moved it: a joint more "
            "than 0.3 rad/s faster than commanded, or moving while the controller commanded a "
            "standstill (a push of 80 N·m on the shoulder pan is more than its servo's 56 N·m; "
            "a part landing on a pocket's rim blocks the arm and springs it back). The "
            "controller stops the task at once, but cannot brake an arm pushed harder than its "
            "motors (a real UR3's protective stop brakes there)."
        )
    return [text, ""]


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true", help="0.5 s holds: a quick look")
    parser.add_argument("--modulus", type=float, help="the parts' hydroelastic modulus [Pa]")
    parser.add_argument(
        "--camera", action="store_true", help="realistic sensors and the camera's verdicts"
    )
    parser.add_argument("--kinds", help="comma-separated cases to run (default: all)")
    args = parser.parse_args(argv)
    cases = CASES if args.kinds is None else args.kinds.split(",")
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"--kinds: unknown {', '.join(unknown)}; the cases are {', '.join(CASES)}")
    extra = (() if args.modulus is None else (modulus_text(args.modulus),)) + (
        (CAMERA_TEXT,) if args.camera else ()
    )
    jobs = []
    for cell in CELLS:
        tasks = run_tasks(cell, args.lean)
        for case in cases:
            for seed in range(args.seeds):
                entry = fault_entry(case, seed, tasks)
                jobs.append((cell, case, seed, entry, args.lean, extra))
    runs, wall = run_pool(one_run, jobs, args.workers)
    text = report(runs, args, wall)
    out = report_path(args)
    if args.lean:
        print(text)  # a quick look: the report keeps the full settings' figures
    else:
        atomic_write_text(out, text)
        print(f"{text}\nwritten to {out}")
    return 0


def report_path(args) -> Path:
    """Where the report of `args` goes: faults.md, faults_E<PA>.md, faults_camera.md."""
    suffix = "" if args.modulus is None else f"_E{args.modulus:g}"
    suffix += "_camera" if args.camera else ""
    return REPORT.with_name(f"faults{suffix}.md")


def run_settings(args) -> tuple[str, str]:
    """(the settings in words, the command's options) of `args`."""
    settings = "lean (0.5 s holds)" if args.lean else "full (5 s holds, TCP <= 0.25 m/s)"
    options = " --lean" if args.lean else ""
    if args.modulus is not None:
        settings += f"; hydroelastic modulus {args.modulus:g} Pa"
        options += f" --modulus {args.modulus:g}"
    if args.camera:
        settings += f"; `{CAMERA_TEXT}`"
        options += " --camera"
    return settings, options + (f" --kinds {args.kinds}" if args.kinds else "")


def report(runs: list[dict], args, wall: float) -> str:
    """The report's Markdown."""
    from importlib.metadata import version

    settings, options = run_settings(args)
    lines = [
        "# Faults: detected and survived",
        "",
        f"`python benchmarks/bench_faults.py --seeds {args.seeds} --workers {args.workers}"
        f"{options}` — drake {version('drake')}, {platform.machine()}, "
        f"{multiprocessing.cpu_count()} cores, Python {platform.python_version()}; "
        f"{len(runs)} runs in {wall / 60:.1f} min of wall time. Settings: {settings}; the "
        "operator's body and the separation monitor on; the operator follows the robot.",
        "",
        "A seed draws the task struck (any of the run's), when (stop and push: 3–6 s into the "
        "task; lost grip: 0.3–1.5 s into the carry), a stop's length (0.5–3 s), how long the "
        "box of a no-path fault stands over the proposed seat (4–9 s), the silence "
        "(11–20 s, past the 10 s timeout), whether the gripper sticks closed (even seeds) or "
        "open (odd), and how far a part slides in the fingers (no-seat: 8–12 mm; at 5 mm a "
        "part may still find its seat). *detected*: "
        "of the faults injected, those the controller found from its measurements (in the "
        "struck task, from the injection on); *out of reach*: of those, the runs whose part "
        "came to rest where the robot has no grasp of it (the planner's verdict on the pose "
        "the sensor reads: tilted past the 0.5 rad a grasp tilted with the part allows, or "
        "lying where the fingers going down would touch the tray or plate), which the cell "
        "hands over (the operator does the task and the assembly goes on); "
        "*recovered*: of the others, the "
        "ones after which the cell went on by itself and finished the assembly; *lost*: "
        "simulated seconds from the injection to the recovery (the operator's done, for a "
        "task handed over), or to the end of a run that stopped.",
        "",
        "| cell | kind | the cell should | runs | injected | detected | out of reach | "
        "recovered | lost, mean [s] | lost, max [s] | collisions | separation violations | "
        "moved from outside |" + (" camera: false | missed | wrong slot |" if args.camera else ""),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        + ("---|" * 3 if args.camera else ""),
        *summary_rows(runs),
        "",
        *violations_note(runs),
        *crash_note(runs),
        *camera_note(runs),
        "## Runs",
        "",
        "| cell | seed | fault | detected at [s] | recovery | terminal | collisions | "
        "separation violations | moved from outside |",
        "|---|---|---|---|---|---|---|---|---|",
        *(
            f"| {r['cell']} | {r['seed']} | `{r['entry']}` | {r['record']['detected_at']} | "
            f"{'crashed' if r.get('crashed') else r['record']['recovery'] or '—'}"
            f"{' (out of reach)' if r['out_of_reach'] else ''} | "
            f"{'yes' if r['terminal'] else 'no'} | "
            f"{r['collisions']} | {r['violations']} | {r['imposed']} |"
            for r in runs
        ),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
