"""The shared desk's safety across populations and settings -> benchmarks/reports/
safety_populations.md.

`shared-desk` (the operator points at the target seat and fetches bolts and nuts beside the
robot's carry path), every operator population, both interaction modes, a few operator seeds, in
the configurations of `CONFIGURATIONS`: monitoring off (the controller's monitor and the
station's safety function both off), monitoring alone and predictive with the tracked person's
speed and with ISO 13855's constant speeds, and both with the person the forecast has not seen
(`body.behaviour: unseen`). Per population and configuration, means over interaction modes and
seeds: the assembly's simulated seconds and their ratio to monitoring off (the price of safety),
steps inside S_p by the run's own check and what it finds beyond ISO/TS 15066 (steps faster than
the body region permits, contacts beyond its force), the seconds in each of the station's safety
modes, and whether every run ended terminal.

Full settings (5 s holds). Usage:
``python benchmarks/bench_safety_populations.py [--seeds 1] [--workers 2] [--lean] [--sensor]``
(with ``--lean`` the report is printed, not written; with ``--sensor`` the function reads the
safety-rated sensor, against monitoring off and today's default, into
``reports/safety_populations_sensor.md``).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

from cell_pool import desk_run, error_lines, publish, run_pool

POPULATIONS = ("follows", "habitual", "mistake-prone", "change-of-mind")
INTERACTIONS = ("anticipate", "wait")
OFF = "monitoring off"
UNSEEN = "body: {behaviour: unseen}"  # the person the forecast has not seen
CONFIGURATIONS = {
    OFF: "{safety: {enabled: false, separation: reactive, function: {enabled: false}}}",
    "monitoring alone, tracked": "{safety: {separation: reactive}}",
    "predictive, tracked": "{safety: {separation: predictive}}",
    "monitoring alone, constant": "{safety: {separation: reactive, human_speed: constant}}",
    "predictive, constant": "{safety: {separation: predictive, human_speed: constant}}",
    "monitoring alone, unseen person": f"{{safety: {{separation: reactive}}, {UNSEEN}}}",
    "predictive, unseen person": f"{{safety: {{separation: predictive}}, {UNSEEN}}}",
}
TODAY = "predictive, tracked"  # the default scenario's settings
SENSOR = "sensor: {enabled: true}"
# With `--sensor`: the safety function reads the safety-rated sensor (`safety.sensor`), against
# monitoring off and today's default. The function then takes constant speeds whatever
# `human_speed` says, so tracked and constant are one configuration.
SENSOR_CONFIGURATIONS = {
    OFF: CONFIGURATIONS[OFF],
    TODAY: CONFIGURATIONS[TODAY],
    "monitoring alone, sensor": f"{{safety: {{separation: reactive, {SENSOR}}}}}",
    "predictive, sensor": f"{{safety: {{separation: predictive, {SENSOR}}}}}",
    "monitoring alone, unseen person, sensor": (
        f"{{safety: {{separation: reactive, {SENSOR}}}, {UNSEEN}}}"
    ),
    "predictive, unseen person, sensor": (
        f"{{safety: {{separation: predictive, {SENSOR}}}, {UNSEEN}}}"
    ),
}
REPORT = Path(__file__).parent / "reports" / "safety_populations.md"
SENSOR_REPORT = Path(__file__).parent / "reports" / "safety_populations_sensor.md"


def one_run(job: tuple) -> dict:
    """One run of (population, interaction, seed, configuration, lean): its figures."""
    population, interaction, seed, configuration, lean = job
    text = {**CONFIGURATIONS, **SENSOR_CONFIGURATIONS}[configuration]
    result = desk_run(population, interaction, seed, text, lean)
    check, function = result.safety_check, result.safety_function
    return {
        "job": job,
        "terminal": result.done,
        "seconds": result.sim_time,
        "inside": check.violations,
        "beyond": check.beyond_permissible + check.contacts_beyond,
        "contacts": check.body_contacts,
        "reduced": function.reduced_time if function is not None else 0.0,
        "stopped": function.stopped_time if function is not None else 0.0,
        "error": result.error,
    }


def rows(runs: list[dict], configurations: dict) -> list[str]:
    """One row per population and configuration (means over interaction modes and seeds); the
    time also as a ratio to today's default (`TODAY`)."""
    lines = [
        "| population | configuration | time [s] | ÷ monitoring off | ÷ today | steps inside S_p "
        "| beyond ISO/TS 15066 | body contacts | normal / reduced / stopped [s] | terminal |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for population in POPULATIONS:
        mine = [r for r in runs if r["job"][0] == population]
        off = statistics.fmean(r["seconds"] for r in mine if r["job"][3] == OFF)
        today = statistics.fmean(r["seconds"] for r in mine if r["job"][3] == TODAY)
        for configuration in configurations:
            these = [r for r in mine if r["job"][3] == configuration]
            if not these:
                continue
            seconds = statistics.fmean(r["seconds"] for r in these)
            reduced = statistics.fmean(r["reduced"] for r in these)
            stopped = statistics.fmean(r["stopped"] for r in these)
            lines.append(
                f"| {population} | {configuration} | {seconds:.2f} | {seconds / off:.3f} | "
                f"{seconds / today:.3f} | "
                f"{sum(r['inside'] for r in these)} | {sum(r['beyond'] for r in these)} | "
                f"{sum(r['contacts'] for r in these)} | {seconds - reduced - stopped:.1f} / "
                f"{reduced:.1f} / {stopped:.1f} | "
                f"{sum(r['terminal'] for r in these)}/{len(these)} |"
            )
    return lines


def report(runs: list[dict], seeds: int, wall: float, lean: bool, sensor: bool = False) -> str:
    """The markdown report."""
    beyond = sum(r["beyond"] for r in runs if r["job"][3] != OFF)
    configurations = SENSOR_CONFIGURATIONS if sensor else CONFIGURATIONS
    lines = [
        "# The shared desk's safety across populations and settings"
        + (", with the safety-rated sensor" if sensor else ""),
        "",
        f"`python benchmarks/bench_safety_populations.py --seeds {seeds}"
        f"{' --sensor' if sensor else ''}"
        f"{' --lean' if lean else ''}`: {len(runs)} runs in {wall / 60:.1f} min on "
        f"{platform.machine()}; `shared-desk`, operator seeds 0–{seeds - 1}, both interaction "
        "modes (means over them).",
        "",
        *rows(runs, configurations),
        "",
        f"With any monitoring: {beyond} step(s) or contact(s) beyond ISO/TS 15066 in "
        f"{sum(r['job'][3] != OFF for r in runs)} runs.",
        "",
    ]
    lines += error_lines(runs)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the configurations and write (or print) the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="operator seeds per population")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true", help="0.5 s holds: a quick look")
    parser.add_argument(
        "--sensor", action="store_true", help="the function reads the safety-rated sensor"
    )
    args = parser.parse_args(argv)
    configurations = SENSOR_CONFIGURATIONS if args.sensor else CONFIGURATIONS
    jobs = [
        (p, i, seed, c, args.lean)
        for p in POPULATIONS
        for i in INTERACTIONS
        for seed in range(args.seeds)
        for c in configurations
    ]
    runs, wall = run_pool(one_run, jobs, args.workers)
    target = SENSOR_REPORT if args.sensor else REPORT
    publish(report(runs, args.seeds, wall, args.lean, args.sensor), target, args.lean)
    return 0


if __name__ == "__main__":
    sys.exit(main())
