"""Separation by the run's own check against the monitor's own count -> benchmarks/reports/
safety_check.md.

The separation monitor counts a violation when the separation falls below the S_p it computes
from what it knows (the hand's speed now, and how fast a hand can speed up); the run's own
check (`hrc_drake.cell.run.safety_check`) counts one when it falls below the S_p of the
person's actual travel over the next T_r + T_s, the same for every mode and setting. This
benchmark runs `shared-desk` (the operator points and fetches beside the carry path) with the
`follows` population, anticipating, on a few operator seeds, in the configurations of
`CONFIGURATIONS`: monitoring off, the controller's planning monitor without the station's safety
function, and monitoring alone and predictive with the tracked speed (bounded by the hand's
acceleration) and with ISO 13855's constant speeds. Per configuration: the assembly's simulated
seconds, `ssm_delay`, both counts and both least margins, body contacts, and the check's
judgement by ISO/TS 15066 Annex A: steps inside S_p faster than the body region permits, contacts
beyond its permissible force, and the approach nearest its permissible speed.

Full settings (5 s holds). Usage:
``python benchmarks/bench_safety_check.py [--seeds 3] [--workers 2] [--lean]`` (with ``--lean``
the report is printed, not written).
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

from cell_pool import desk_run, publish, run_pool

CONFIGURATIONS = {
    # The controller's monitor and the station's safety function both off.
    "monitoring off": (
        "{safety: {enabled: false, separation: reactive, function: {enabled: false}}}"
    ),
    # The controller's planning monitor alone, without the station's safety function.
    "planning monitor only, tracked": (
        "{safety: {separation: reactive, function: {enabled: false}}}"
    ),
    "monitoring alone, tracked": "{safety: {separation: reactive}}",
    "predictive, tracked": "{safety: {separation: predictive}}",
    "monitoring alone, constant": "{safety: {separation: reactive, human_speed: constant}}",
    "predictive, constant": "{safety: {separation: predictive, human_speed: constant}}",
}
POPULATION, INTERACTION = "follows", "anticipate"
REPORT = Path(__file__).parent / "reports" / "safety_check.md"


def one_run(job: tuple) -> dict:
    """One run of (configuration, seed, lean): its figures."""
    configuration, seed, lean = job
    result = desk_run(POPULATION, INTERACTION, seed, CONFIGURATIONS[configuration], lean)
    monitor, check = result.safety, result.safety_check
    return {
        "job": job,
        "terminal": result.done,
        "seconds": result.sim_time,
        "ssm_delay": monitor.ssm_delay,
        "monitor_violations": monitor.violations,
        "monitor_margin": monitor.min_margin,
        "violations": check.violations,
        "least_margin": check.least_margin,
        "body_contacts": check.body_contacts,
        "beyond": check.beyond_permissible,
        "contacts_beyond": check.contacts_beyond,
        "nearest": None if check.worst is None else check.worst.to_json(),
        "error": result.error,
    }


def _range(values, form: str = ".1f") -> str:
    low, high = min(values), max(values)
    return f"{low:{form}}" if f"{low:{form}}" == f"{high:{form}}" else f"{low:{form}}–{high:{form}}"


def _nearest(rows: list[dict]) -> str:
    """The approach inside S_p nearest (or furthest beyond) its permissible speed, of `rows`:
    speed of permitted, toward which region."""
    judged = [r["nearest"] for r in rows if r["nearest"] is not None]
    if not judged:
        return "—"

    def over(j):
        return j["speed"] / j["permissible_speed"] if j["permissible_speed"] else float("inf")

    j = max(judged, key=over)
    return f"{j['speed']:.2f} of {j['permissible_speed']:.2f} ({j['region']})"


def report(runs: list[dict], seeds: int, wall: float, lean: bool) -> str:
    """The markdown report."""
    lines = [
        "# Separation: the run's own check against the monitor's own count",
        "",
        f"`shared-desk`, population `{POPULATION}`, {INTERACTION}, operator seeds 0–{seeds - 1}"
        f"{' (lean)' if lean else ''}; one run each. `python benchmarks/bench_safety_check.py "
        f"--seeds {seeds}` on {platform.machine()}, {wall:.0f} s wall.",
        "",
        "| configuration | time [s] | ssm_delay [s] | violations: monitor / check | least "
        "margin [m]: monitor / check | body contacts | beyond ISO/TS 15066: steps / contacts | "
        "nearest its limit [m/s] | terminal |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for configuration in CONFIGURATIONS:
        rows = [r for r in runs if r["job"][0] == configuration]
        monitor = ", ".join(str(r["monitor_violations"]) for r in rows)
        check = ", ".join(str(r["violations"]) for r in rows)
        lines.append(
            f"| {configuration} | {_range([r['seconds'] for r in rows])} | "
            f"{_range([r['ssm_delay'] for r in rows])} | {monitor} / {check} | "
            f"{min(r['monitor_margin'] for r in rows):+.3f} / "
            f"{min(r['least_margin'] for r in rows):+.3f} | "
            f"{sum(r['body_contacts'] for r in rows)} | "
            f"{sum(r['beyond'] for r in rows)} / {sum(r['contacts_beyond'] for r in rows)} | "
            f"{_nearest(rows)} | {sum(r['terminal'] for r in rows)}/{len(rows)} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """Run the configurations and write (or print) the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--lean", action="store_true")
    args = parser.parse_args(argv)
    jobs = [(c, s, args.lean) for c in CONFIGURATIONS for s in range(args.seeds)]
    runs, wall = run_pool(one_run, jobs, args.workers)
    publish(report(runs, args.seeds, wall, args.lean), REPORT, args.lean)
    return 0


if __name__ == "__main__":
    sys.exit(main())
