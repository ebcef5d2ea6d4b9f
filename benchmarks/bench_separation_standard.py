"""Separation the standard accepts, and what predictive motion buys -> benchmarks/reports/
separation_standard.md.

`shared-desk` (the operator points at the seat and fetches bolts and nuts beside the carry path),
every operator population, both interaction modes, the same operator seeds, in each separation
configuration below; then monitoring alone and predictive against a person the forecast has not
seen (`body.behaviour: unseen`). Every run is judged by the run's own check
(`hrc_drake.cell.run.safety_check`): violations and body contacts. The report gives, per
configuration, the check's counts and the mean time, then the ratios the issue asks for:
predictive's mean time over the fastest monitoring-alone configuration with 0 violations, over
monitoring alone at constant speed, and the price of safety (predictive over monitoring off) per
population and interaction mode.

With ``--separation-alone`` every configuration keeps S_p by separation alone (no contact-speed
allowance, `safety.contact_speed: 0`) and the operator's hand rests behind the table edge
(`ALONE`: inside S_p of the placing pose, where it rests by default, separation alone crawls);
the report goes to `separation_standard_alone.md`.

Usage: ``python benchmarks/bench_separation_standard.py [--seeds 4] [--workers 2] [--lean]
[--separation-alone] [--only NAME ...] [--out PATH]``; ``--only`` runs the configurations
named (keys of `CONFIGURATIONS`). The report is written (with ``--lean`` too: the settings
are stated in it).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

from cell_pool import pooled_loop, run_pool, write_report

POPULATIONS = ("follows", "habitual", "mistake-prone", "change-of-mind")
INTERACTIONS = ("anticipate", "wait")
OFF = "monitoring off"
CONFIGURATIONS = {
    # The baseline: the controller's monitor and the station's safety function both off.
    OFF: "{safety: {enabled: false, separation: reactive, function: {enabled: false}}}",
    "monitoring alone, tracked": "{safety: {separation: reactive}}",
    "monitoring alone, constant": "{safety: {separation: reactive, human_speed: constant}}",
    "predictive (waits), tracked": "{safety: {separation: predictive}}",
    "predictive (path-time), tracked": ("{safety: {separation: predictive, timing: path_time}}"),
    "predictive (waits), constant": ("{safety: {separation: predictive, human_speed: constant}}"),
    "monitoring alone, tracked, unseen person": (
        "{safety: {separation: reactive}, body: {behaviour: unseen}}"
    ),
    "predictive (waits), tracked, unseen person": (
        "{safety: {separation: predictive}, body: {behaviour: unseen}}"
    ),
}
MONITORING_ALONE = [
    c for c in CONFIGURATIONS if c.startswith("monitoring alone") and "unseen" not in c
]
PREDICTIVE = [c for c in CONFIGURATIONS if c.startswith("predictive") and "unseen" not in c]
REPORT = Path(__file__).parent / "reports" / "separation_standard.md"
REPORT_ALONE = REPORT.with_name("separation_standard_alone.md")
ALONE = "{safety: {contact_speed: 0.0}, body: {rest_hand: [0.9, 0.10, 0.06]}}"


def one_run(job: tuple) -> dict:
    """One run of (configuration, population, interaction, seed, lean, alone): its figures."""
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    configuration, population, interaction, seed, lean, alone = job
    operator = (
        f"{{operator: {{model: {population}, seed: {seed}}}, interaction: {{mode: {interaction}}}}}"
    )
    texts = [operator, CONFIGURATIONS[configuration], *([ALONE] if alone else [])]
    texts += [LEAN] if lean else []
    scenario = load_cell_scenario("shared-desk", texts)
    result = pooled_loop(scenario, scenario.assembly).run()
    check = result.safety_check
    function = result.safety_function
    return {
        "job": job,
        "terminal": result.done,
        "seconds": result.sim_time,
        "violations": check.violations,
        "body_contacts": check.body_contacts,
        "least_margin": check.least_margin,
        "beyond_contact_speed": check.beyond_contact_speed,
        "stops": 0 if function is None else function.safeguard_stops + function.protective_stops,
        "error": result.error,
    }


def _mean(runs: list[dict]) -> float:
    return statistics.fmean(r["seconds"] for r in runs)


def _of(runs: list[dict], configuration: str, population=None, interaction=None) -> list[dict]:
    return [
        r
        for r in runs
        if r["job"][0] == configuration
        and population in (None, r["job"][1])
        and interaction in (None, r["job"][2])
    ]


def _run(runs: list[dict], configurations) -> list[str]:
    """Those of `configurations` that `runs` ran (`--only`)."""
    return [c for c in configurations if _of(runs, c)]


def configuration_rows(runs: list[dict]) -> list[str]:
    """Per configuration: the check's counts, the function's stops, the times."""
    lines = [
        "| configuration | runs | terminal | violations (runs with any) | of them beyond the "
        "contact speed | body contacts | least margin [m] | safety function stops | mean time "
        "[s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for configuration in _run(runs, CONFIGURATIONS):
        rows = _of(runs, configuration)
        violating = sum(1 for r in rows if r["violations"])
        margin = min(r["least_margin"] for r in rows)
        lines.append(
            f"| {configuration} | {len(rows)} | {sum(r['terminal'] for r in rows)} | "
            f"{sum(r['violations'] for r in rows)} ({violating}) | "
            f"{sum(r['beyond_contact_speed'] for r in rows)} | "
            f"{sum(r['body_contacts'] for r in rows)} | "
            f"{'—' if margin == float('inf') else f'{margin:+.3f}'} | "
            f"{sum(r['stops'] for r in rows)} | {_mean(rows):.2f} |"
        )
    return lines


def ratio_lines(runs: list[dict]) -> list[str]:
    """Predictive against the fastest compliant monitoring alone and against constant speed."""
    alone, predictive = _run(runs, MONITORING_ALONE), _run(runs, PREDICTIVE)
    compliant = [c for c in alone if not any(r["violations"] for r in _of(runs, c))]
    lines = []
    if compliant:
        fastest = min(compliant, key=lambda c: _mean(_of(runs, c)))
        lines.append(
            f"The fastest monitoring-alone configuration with 0 violations: **{fastest}**, "
            f"{_mean(_of(runs, fastest)):.2f} s."
        )
        for c in predictive:
            ratio = _mean(_of(runs, c)) / _mean(_of(runs, fastest))
            lines.append(f"- {c} ÷ {fastest}: **{ratio:.3f}** (goal ≤ 0.80)")
    else:
        lines.append("No monitoring-alone configuration had 0 violations.")
    constant = "monitoring alone, constant"
    for c in predictive if _of(runs, constant) else ():
        ratio = _mean(_of(runs, c)) / _mean(_of(runs, constant))
        lines.append(f"- {c} ÷ {constant}: **{ratio:.3f}** (do no harm: ≤ 1.00)")
    return lines


def price_rows(runs: list[dict]) -> list[str]:
    """The price of safety, per population and interaction mode: each predictive configuration
    (and monitoring alone) over monitoring off."""
    shown = _run(runs, ["monitoring alone, tracked", *PREDICTIVE])
    if not _of(runs, OFF):
        return ["(monitoring off was not run)"]
    lines = [
        "| population | mode | " + " | ".join(shown) + " |",
        "|---|---|" + "---|" * len(shown),
    ]
    for population in POPULATIONS:
        for interaction in INTERACTIONS:
            off = _mean(_of(runs, OFF, population, interaction))
            cells = [f"{_mean(_of(runs, c, population, interaction)) / off:.3f}" for c in shown]
            lines.append(f"| {population} | {interaction} | " + " | ".join(cells) + " |")
    return lines


def report(runs: list[dict], args, wall: float) -> str:
    """The markdown report."""
    failed = [r for r in runs if not r["terminal"]]
    only = " --only" + "".join(f" {c!r}" for c in args.only) if args.only else ""
    lines = [
        "# Separation the standard accepts, and predictive motion",
        "",
        f"`shared-desk`, populations {', '.join(POPULATIONS)}, interaction "
        f"{' and '.join(INTERACTIONS)}, operator seeds 0–{args.seeds - 1}; one run each, "
        f"{'lean settings (`--lean`: 0.5 s holds)' if args.lean else 'full settings'}"
        f"{f'; separation alone, every run with `{ALONE}`' if args.separation_alone else ''}. "
        f"`python benchmarks/bench_separation_standard.py --seeds {args.seeds}"
        f"{' --lean' if args.lean else ''}{' --separation-alone' if args.separation_alone else ''}"
        f"{only}"
        f"` on {platform.machine()}, {len(runs)} runs, {wall:.0f} s wall.",
        "",
        "Violations and body contacts are the run's own check's (S_h: the person's actual "
        "travel): samples where the robot moved under its own command closer than S_p. Of "
        "them, those where it also moved toward the person faster than 0.25 m/s (ISO "
        "10218-1's reduced speed) or toward the head, which power and force limiting would not "
        "permit either. Safety function stops: the station's safeguard and protective stops.",
        "",
        *configuration_rows(runs),
        "",
        "## Ratios (mean assembly time)",
        "",
        *ratio_lines(runs),
        "",
        "## The price of safety (÷ monitoring off), per population and mode",
        "",
        *price_rows(runs),
        "",
    ]
    if failed:
        lines += ["## Runs that did not end terminal", ""]
        lines += [f"- {r['job'][:4]}: {r['error']}" for r in failed]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    """Run every configuration on every population, mode and seed; write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true")
    parser.add_argument("--separation-alone", action="store_true")
    parser.add_argument("--only", nargs="+", choices=list(CONFIGURATIONS), metavar="NAME")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    out = args.out or (REPORT_ALONE if args.separation_alone else REPORT)
    jobs = [
        (c, p, i, s, args.lean, args.separation_alone)
        for c in args.only or CONFIGURATIONS
        for p in POPULATIONS
        for i in INTERACTIONS
        for s in range(args.seeds)
    ]
    runs, wall = run_pool(one_run, jobs, args.workers)
    write_report(report(runs, args, wall), out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
