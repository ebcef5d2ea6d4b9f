"""Separation by the run's own check over the whole catalogue ->
benchmarks/reports/separation_catalogue.md.

Every catalogue scenario (`scenarios/*.yaml`) runs lean (0.5 s holds) with monitoring alone and
with predictive separation, each with the tracked (bounded) and the constant human speed: the
first Done-when item of issue 30 over the catalogue, where `bench_separation_standard.py` runs
`shared-desk`'s populations. With ``--separation-alone`` every run keeps S_p by separation alone
(`bench_separation_standard.ALONE`: no contact-speed allowance, the resting hand behind the
table edge). Each row: whether the run ended terminal in the states `react` visits for the
scenario (`bench_camera.expected_names`), the check's violations (and those beyond the contact
speed) and body contacts, the station's safety-function stops, and the simulated time. The
report goes to `separation_catalogue.md`, with ``--separation-alone`` to
`separation_catalogue_alone.md`.

Usage: ``python benchmarks/bench_separation_catalogue.py [--separation-alone] [--workers 2]
[--only NAME ...] [--out PATH]``.
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

from bench_separation_standard import ALONE
from cell_pool import pooled_loop, run_pool, write_report

from hrc_drake.resources import scenarios_dir

CONFIGURATIONS = {
    "monitoring alone, tracked": "{safety: {separation: reactive}}",
    "monitoring alone, constant": "{safety: {separation: reactive, human_speed: constant}}",
    "predictive, tracked": "{safety: {separation: predictive}}",
    "predictive, constant": "{safety: {separation: predictive, human_speed: constant}}",
}
REPORT = Path(__file__).parent / "reports" / "separation_catalogue.md"
REPORT_ALONE = REPORT.with_name("separation_catalogue_alone.md")


def one_run(job: tuple) -> dict:
    """One lean run of (scenario name, configuration, alone): its figures."""
    from bench_camera import expected_names

    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    name, configuration, alone = job
    texts = [LEAN, CONFIGURATIONS[configuration], *([ALONE] if alone else [])]
    scenario = load_cell_scenario(name, texts)
    result = pooled_loop(scenario, scenario.assembly).run()
    check, function = result.safety_check, result.safety_function
    return {
        "job": job,
        "in_states": result.done and result.names == expected_names(scenario),
        "violations": check.violations,
        "beyond": check.beyond_contact_speed,
        "contacts": check.body_contacts,
        "stops": 0 if function is None else function.safeguard_stops + function.protective_stops,
        "seconds": result.sim_time,
    }


def report(runs: list[dict], args, wall: float) -> str:
    """The markdown report."""
    rows = [
        f"| {r['job'][0]} | {r['job'][1]} | {'yes' if r['in_states'] else '**no**'} | "
        f"{r['violations']} ({r['beyond']}) | {r['contacts']} | {r['stops']} | "
        f"{r['seconds']:.1f} |"
        for r in runs
    ]
    missed = sum(not r["in_states"] for r in runs)
    totals = (
        f"{len(runs)} runs: {len(runs) - missed} terminal in their states, "
        f"{sum(r['violations'] for r in runs)} violations "
        f"({sum(r['beyond'] for r in runs)} beyond the contact speed), "
        f"{sum(r['contacts'] for r in runs)} body contacts, "
        f"{sum(r['stops'] for r in runs)} safety-function stops."
    )
    alone = f"; separation alone, every run with `{ALONE}`" if args.separation_alone else ""
    return "\n".join(
        [
            "# Separation by the run's own check over the catalogue",
            "",
            f"Every catalogue scenario, lean (0.5 s holds){alone}. "
            f"`python benchmarks/bench_separation_catalogue.py"
            f"{' --separation-alone' if args.separation_alone else ''}` on "
            f"{platform.machine()}, {wall:.0f} s wall.",
            "",
            totals,
            "",
            "| scenario | configuration | terminal in its states | violations (beyond the "
            "contact speed) | body contacts | safety-function stops | simulated [s] |",
            "|---|---|---|---|---|---|---|",
            *rows,
            "",
        ]
    )


def main(argv=None) -> int:
    """Run every configuration on every catalogue scenario; write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--separation-alone", action="store_true")
    parser.add_argument("--workers", type=int, default=2)
    catalogue = sorted(p.stem for p in scenarios_dir().glob("*.yaml"))
    parser.add_argument("--only", nargs="+", metavar="NAME", choices=catalogue)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    out = args.out or (REPORT_ALONE if args.separation_alone else REPORT)
    names = args.only or catalogue
    jobs = [(n, c, args.separation_alone) for n in names for c in CONFIGURATIONS]
    runs, wall = run_pool(one_run, jobs, args.workers)
    write_report(report(runs, args, wall), out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
