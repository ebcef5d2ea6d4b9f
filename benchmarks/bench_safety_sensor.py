"""The safety-rated sensor's price -> benchmarks/reports/safety_sensor.md.

With `safety.sensor.enabled` the station's safety function reads three 3D safety cameras over
the desk instead of the simulated body, and so takes ISO 13855's constant speeds (it measures no
one's speed) and a T_r lengthened by the cameras' response time; the controller plans by the
same settings. This benchmark runs `shared-desk` (operator seeds of the `follows` population,
anticipating) and `row5-forces-5` in three settings — today's (the function reads the body,
tracked speeds), the same with ISO 13855's constant speeds, those with the sensor's T_r (its
settings without it: what the standard's figures cost alone) and the safety sensor — and reports
per setting the assembly's simulated seconds and their ratio to today's, the safety function's
stops, the run's own check by ISO/TS 15066 (steps beyond the permissible speed, contacts beyond
the permissible force, body contacts) and the wall seconds per simulated second (what the sensor
costs the simulation). Then every catalogue scenario, lean (as CI runs them), today and with
the sensor: terminal, the check passed, what is beyond ISO/TS 15066, and the time's ratio.

Full settings (5 s holds) for the first table. Usage:
``python benchmarks/bench_safety_sensor.py [--seeds 3] [--workers 2] [--lean]`` (with ``--lean``
the report is printed, not written, and the catalogue is left out).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

from cell_pool import desk_run, error_lines, pooled_loop, publish, run_pool

SETTINGS = {
    "today (the body itself, tracked)": "{safety: {separation: predictive}}",
    "the body itself, constant": "{safety: {separation: predictive, human_speed: constant}}",
    # The sensor's settings without the sensor: what the standard's figures cost alone.
    "the body itself, constant, T_r + 55 ms": (
        "{safety: {separation: predictive, human_speed: constant, reaction_time: 0.155}}"
    ),
    "safety sensor": "{safety: {separation: predictive, sensor: {enabled: true}}}",
}
POPULATION, INTERACTION = "follows", "anticipate"
ROW = "row5-forces-5"
REPORT = Path(__file__).parent / "reports" / "safety_sensor.md"


# The catalogue's settings: today's default, and the sensor on.
CATALOGUE = {
    "lean, today": "{}",
    "lean, safety sensor": "{safety: {sensor: {enabled: true}}}",
}


def one_run(job: tuple) -> dict:
    """One run of (scenario, setting, seed, lean): its figures."""
    scenario, setting, seed, lean = job
    start = time.perf_counter()
    if setting in CATALOGUE:
        from hrc_drake.cell.scenario import LEAN, load_cell_scenario

        loaded = load_cell_scenario(scenario, [CATALOGUE[setting], LEAN])
        result = pooled_loop(loaded, loaded.assembly).run()
    elif scenario == "shared-desk":
        result = desk_run(POPULATION, INTERACTION, seed, SETTINGS[setting], lean)
    else:
        from hrc_drake.cell.scenario import LEAN, load_cell_scenario

        loaded = load_cell_scenario(scenario, [SETTINGS[setting], *([LEAN] if lean else [])])
        result = pooled_loop(loaded, loaded.assembly).run()
    wall = time.perf_counter() - start
    check, function = result.safety_check, result.safety_function
    if check is None:  # no body in the scene
        return {"job": job, "terminal": result.done, "seconds": result.sim_time, "passed": None}
    return {
        "job": job,
        "terminal": result.done,
        "seconds": result.sim_time,
        "wall_per_second": wall / max(result.sim_time, 1e-9),
        "stops": function.safeguard_stops + function.protective_stops,
        "beyond": check.beyond_permissible,
        "contacts_beyond": check.contacts_beyond,
        "body_contacts": check.body_contacts,
        "passed": check.passed,
        "error": result.error,
    }


def _mean(values) -> float:
    values = list(values)
    return sum(values) / len(values)


def catalogue_table(runs: list[dict]) -> list[str]:
    """The catalogue's rows: today's time and the sensor's, terminal, the check."""
    lines = [
        "",
        "Every catalogue scenario, lean (0.5 s holds, as CI runs them), today and with the sensor:",
        "",
        "| scenario | today [s] | with the sensor [s] | × today | terminal | check passed | "
        "beyond ISO/TS 15066: steps / contacts | stops |",
        "|---|---|---|---|---|---|---|---|",
    ]
    names = sorted({r["job"][0] for r in runs if r["job"][1] in CATALOGUE})
    for name in names:
        today, sensor = (
            next(r for r in runs if r["job"][:2] == (name, setting)) for setting in CATALOGUE
        )
        passed = "—" if sensor["passed"] is None else "yes" if sensor["passed"] else "NO"
        lines.append(
            f"| {name} | {today['seconds']:.1f} | {sensor['seconds']:.1f} | "
            f"×{sensor['seconds'] / today['seconds']:.2f} | "
            f"{'yes' if today['terminal'] and sensor['terminal'] else 'NO'} | {passed} | "
            f"{sensor.get('beyond', '—')} / {sensor.get('contacts_beyond', '—')} | "
            f"{sensor.get('stops', '—')} |"
        )
    return lines


def report(runs: list[dict], seeds: int, wall: float, lean: bool) -> str:
    """The markdown report."""
    lines = [
        "# The safety sensor's price",
        "",
        f"`shared-desk` (population `{POPULATION}`, {INTERACTION}, operator seeds 0–{seeds - 1})"
        f" and `{ROW}`{' (lean)' if lean else ''}; one run each. `python "
        f"benchmarks/bench_safety_sensor.py --seeds {seeds}` on {platform.machine()}, "
        f"{wall:.0f} s wall.",
        "",
        "| scenario | setting | mean time [s] | × today | safety function stops | beyond ISO/TS "
        "15066: steps / contacts | body contacts | wall s per sim s | terminal |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for scenario in ("shared-desk", ROW):
        base = None
        for setting in SETTINGS:
            rows = [r for r in runs if r["job"][0] == scenario and r["job"][1] == setting]
            mean = _mean(r["seconds"] for r in rows)
            base = mean if base is None else base
            lines.append(
                f"| {scenario} | {setting} | {mean:.1f} | ×{mean / base:.2f} | "
                f"{sum(r['stops'] for r in rows)} | {sum(r['beyond'] for r in rows)} / "
                f"{sum(r['contacts_beyond'] for r in rows)} | "
                f"{sum(r['body_contacts'] for r in rows)} | "
                f"{_mean(r['wall_per_second'] for r in rows):.2f} | "
                f"{sum(r['terminal'] for r in rows)}/{len(rows)} |"
            )
    if any(r["job"][1] in CATALOGUE for r in runs):
        lines += catalogue_table(runs)
    errors = error_lines(runs)
    return "\n".join([*lines, *([""] if errors else []), *errors]) + "\n"


def main(argv=None) -> int:
    """Run the settings and write (or print) the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true")
    args = parser.parse_args(argv)
    jobs = [("shared-desk", s, seed, args.lean) for s in SETTINGS for seed in range(args.seeds)]
    jobs += [(ROW, s, 0, args.lean) for s in SETTINGS]
    if not args.lean:
        from hrc_drake.resources import scenarios_dir

        names = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))
        jobs += [(name, s, 0, True) for name in names for s in CATALOGUE]
    runs, wall = run_pool(one_run, jobs, args.workers)
    publish(report(runs, args.seeds, wall, args.lean), REPORT, args.lean)
    return 0


if __name__ == "__main__":
    sys.exit(main())
