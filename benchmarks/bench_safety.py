"""The operator's body and speed and separation monitoring: what they cost and what they add.

Writes benchmarks/reports/safety.md:
- real-time factor of the same run with the body and monitoring on and off, side by side;
- the controller's separation monitor's cost per step (forward kinematics, the distance of every
  body sphere to every robot shape, S_p);
- per Table 2 row (and the stochastic scenarios) with full settings: the simulated assembly
  time with and without the body, the time added by slowing and stopping, and the safety
  figures (target: ≤ 10 % added);
- row 1 with the person's speed not tracked (v_h = 1.6 m/s throughout), for contrast.

Usage: python benchmarks/bench_safety.py [--rows 1,4] [--lean] [--out report.md]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.controller.separation import ControllerSeparationMonitor
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN
from hrc_drake.scenario.load import table2_scenarios

REPORT = Path(__file__).parent / "reports" / "safety.md"
OFF = "{body: {enabled: false}}"
UNTRACKED = "{safety: {human_speed: constant}}"
STOCHASTIC = ("stochastic-mistakes", "stochastic-long")


class _Timer:
    """Wall time and calls of the controller's monitor's reading (one per Supervisor step), and
    the body spheres it assessed."""

    def __init__(self):
        self.calls, self.seconds, self.spheres = 0, 0.0, 0
        self._reading = ControllerSeparationMonitor._calc_reading

    def __enter__(self):
        timer = self

        def reading(monitor, context, output):
            start = time.perf_counter()
            timer._reading(monitor, context, output)
            timer.seconds += time.perf_counter() - start
            timer.calls += 1
            timer.spheres += len(monitor.GetInputPort("operator.body").Eval(context).radii)

        ControllerSeparationMonitor._calc_reading = reading
        return self

    def __exit__(self, *exc):
        ControllerSeparationMonitor._calc_reading = self._reading


def _texts(lean: bool, *extra: str) -> list[str]:
    return [t for t in (LEAN if lean else None, *extra) if t]


def main() -> None:
    """Run the benchmark and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rows", default="", help="Table 2 rows to run (default: all)")
    parser.add_argument("--lean", action="store_true", help="0.5 s holds instead of 5 s")
    parser.add_argument("--out", type=Path, default=REPORT)
    args = parser.parse_args()
    rows = table2_scenarios()
    if args.rows:
        wanted = {int(r) for r in args.rows.split(",")}
        rows = [r for r in rows if r.table2_row in wanted]
    names = [r.name for r in rows] + ([] if args.rows else list(STOCHASTIC))
    settings = "lean (0.5 s holds)" if args.lean else "full (5 s holds, TCP <= 0.25 m/s)"
    lines = [
        "# The operator's body and speed and separation monitoring",
        "",
        f"Command: `python benchmarks/bench_safety.py{' --lean' if args.lean else ''}`. "
        f"Settings: {settings}. Each run is simulated with the body and monitoring on (the "
        f"default) and off (`{OFF}`); the motion planner's cache is warm for both (a first, "
        "untimed run of row 1 fills it), so wall times compare physics and control only.",
        "",
    ]
    run_scenario(names[0], scenario_text=_texts(args.lean))  # warm the plan cache

    # 1. Real-time factor, same run on and off.
    with _Timer() as timer:
        on = run_scenario(names[0], scenario_text=_texts(args.lean))
    off = run_scenario(names[0], scenario_text=_texts(args.lean, OFF))
    lines += [
        "## Real-time factor, the same run with the body and monitoring on and off",
        "",
        "| run | simulated [s] | wall [s] | real-time factor |",
        "|---|---|---|---|",
        f"| {names[0]}, body + monitoring on | {on.sim_time:.1f} | {on.wall_time:.1f} | "
        f"{on.real_time_factor:.2f} |",
        f"| {names[0]}, off | {off.sim_time:.1f} | {off.wall_time:.1f} | "
        f"{off.real_time_factor:.2f} |",
        "",
        "## Cost of the controller's separation monitor per Supervisor step (20 ms)",
        "",
        f"{timer.calls} steps; {1e3 * timer.seconds / max(timer.calls, 1):.2f} ms of wall time "
        f"per step (forward kinematics of its own robot model, the distance of each of the "
        f"body's {timer.spheres / max(timer.calls, 1):.0f} spheres to every robot shape, S_p); "
        f"{100 * timer.seconds / max(on.wall_time, 1e-9):.0f} % of the run's wall time.",
        "",
    ]

    # 2. Assembly time added, per row.
    lines += [
        "## Assembly time added by slowing and stopping",
        "",
        "| scenario | states | ok | simulated off [s] | on [s] | added | slowed [s] | "
        "stopped [s] | least separation [m] | least margin moving [m] | steps inside S_p | "
        "body contacts |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    worst = 0.0
    for name in names:
        runs = {}
        for label, texts in (("on", _texts(args.lean)), ("off", _texts(args.lean, OFF))):
            runs[label] = run_scenario(name, scenario_text=texts)
            print(f"{name} {label}: {runs[label].sim_time:.1f} s simulated", flush=True)
        a, b = runs["on"], runs["off"]
        added = (a.sim_time - b.sim_time) / b.sim_time
        worst = max(worst, added)
        safety = a.to_json()["safety"]
        s, check = safety["monitor"], safety["check"]  # the monitor's figures, the run's check
        lines.append(
            f"| {name} | {' '.join(a.names)} | {'yes' if a.done and a.states == b.states else 'NO'}"
            f" | {b.sim_time:.1f} | {a.sim_time:.1f} | {100 * added:+.1f} % | "
            f"{s['slowed_time']:.2f} | {s['stopped_time']:.2f} | {s['min_separation']} | "
            f"{s['min_margin']} | {check['steps_inside_sp']} | {check['body_contacts']} |"
        )
        for label, r in runs.items():
            if r.error:
                lines.append(f"|  | {name} {label}: {r.error} |")
    lines += ["", f"Largest time added: {100 * worst:+.1f} % (target <= 10 %).", ""]

    # 3. Untracked person speed, for contrast.
    untracked = run_scenario(names[0], scenario_text=_texts(args.lean, UNTRACKED))
    s = untracked.to_json()["safety"]["monitor"]
    inside = untracked.to_json()["safety"]["check"]["steps_inside_sp"]
    lines += [
        "## The person's speed not tracked (v_h = 1.6 m/s throughout)",
        "",
        f"{names[0]} with `{UNTRACKED}`: {untracked.sim_time:.1f} s simulated "
        f"({100 * (untracked.sim_time - off.sim_time) / off.sim_time:+.1f} % over the run "
        f"without the body), slowed {s['slowed_time']:.1f} s, stopped "
        f"{s['stopped_time']:.1f} s, {inside} steps inside S_p"
        + (f"; error: {untracked.error}" if untracked.error else "; reaches its terminal state")
        + ".",
        "",
    ]
    atomic_write_text(args.out, "\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
