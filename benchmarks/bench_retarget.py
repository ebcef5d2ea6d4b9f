"""How soon a re-target's plan is ready -> benchmarks/reports/retarget.md.

In `anticipate` mode a robot carrying the part it bet on to the wrong seat turns to the
indicated one at its plan's next rest point (`hrc_drake.cell.controller.anticipation`): the lift's
end, or once past it the pre-place pose. The turn's plan carries the part on from there (a held
plan). At a commitment the Supervisor asks ahead for up to `RETARGETS_AHEAD` of them from the lift's
end; one indicated after the lift's end is asked at the indication and planned during the carry.

For every re-target bet of the flange case and the 4-slot and 5-slot cells (a state, the
placement committed to, another seat for the same kind of part), this plans the committed
task, then the held plan from the lift's end and from the pre-place pose, timing each call
(in process, a fresh planner per cell; wall seconds on this machine). The arm would stop for a
plan only if it came late, so per interface the *latency* — how long a real-time arm would
stand at the rest point waiting for its plan — is taken over 10,000 indication times drawn
from the interface's delay: before the lift's end, the plans asked ahead at the commitment in
order (latency: when the indicated one is done, past the lift's end); during the carry, the
plan asked at the indication (latency: past the pre-place pose); at the pre-place pose (the
robot there, waiting), all of the plan's time. Target: median latency under 50 ms.

Usage: ``python benchmarks/bench_retarget.py [--samples 10000]``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.controller.anticipation import RETARGETS_AHEAD, lift_end, same_part, wait_point
from hrc_drake.cell_models import CellDesign
from hrc_drake.motion.planner import MotionPlanner
from hrc_drake.resources import models_dir
from hrc_drake.tasks.costs import bet_pairs
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.interaction import DEFAULT_DELAYS, INTERFACES
from hrc_drake.tasks.spec import load_spec

CELLS = ("flange", "four-slot", "five-slot")
REPORT = Path(__file__).parent / "reports" / "retarget.md"


def retarget_bets(space) -> dict[tuple, list[str]]:
    """(state, committed) -> the other seats of the same part, for every re-target bet."""
    bets: dict[tuple, list[str]] = {}
    for state, committed, indicated in bet_pairs(space):
        if same_part(space.spec, committed, indicated):
            bets.setdefault((state, committed), []).append(indicated)
    return bets


def timed(planner: MotionPlanner, configuration, task, **kwargs):
    """(plan, wall seconds) of one planner call."""
    start = time.perf_counter()
    plan = planner.plan_task(configuration, task, **kwargs)
    return plan, time.perf_counter() - start


def measure(cell: str) -> list[dict]:
    """Per re-target bet of `cell`: the committed plan's lift's end and pre-place times, and
    the held plans' planning seconds from each (the ones asked ahead in their order)."""
    space = generate_states(load_spec(models_dir() / "assemblies" / f"{cell}.yaml"))
    planner = MotionPlanner(design=CellDesign.of(space.spec))
    rows = []
    for (state, committed), others in retarget_bets(space).items():
        configuration = space.configuration(space.index(state))
        last = state[-1] if state else None
        plan, _ = timed(planner, configuration, committed, last_token=last)
        turns = {"lift": lift_end(plan), "pre-place": wait_point(plan)}
        seconds: dict[str, dict[str, float]] = {"lift": {}, "pre-place": {}}
        for where, tau in turns.items():
            q = plan.trajectory.value(tau).ravel()
            for task in others:
                _, wall = timed(
                    planner,
                    configuration,
                    task,
                    last_token=last,
                    instance=plan.instance,
                    q_start=q,
                    held=True,
                )
                seconds[where][task] = wall
        rows.append(
            {"cell": cell, "state": state, "committed": committed, "turns": turns, **seconds}
        )
        print(f"\r{cell}: {len(rows)} bets", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return rows


def latencies(row: dict, task: str, indications: np.ndarray) -> np.ndarray:
    """How long a real-time arm would wait at its rest point for the re-target to `task`,
    for each indication time (s after the commitment)."""
    lift, place = row["turns"]["lift"], row["turns"]["pre-place"]
    ahead = list(row["lift"])[:RETARGETS_AHEAD]
    if task in ahead:  # asked at the commitment, after those before it
        done = sum(row["lift"][t] for t in ahead[: ahead.index(task) + 1])
        early = max(0.0, done - lift)
    else:  # asked at the indication
        early = row["lift"][task]
    carrying = np.maximum(0.0, indications + row["pre-place"][task] - place)
    waiting = np.full_like(indications, row["pre-place"][task])
    return np.where(indications < lift, early, np.where(indications < place, carrying, waiting))


def report(rows: list[dict], samples: int, wall: float) -> str:
    """The report's Markdown."""
    from importlib.metadata import version

    rng = np.random.default_rng(0)
    lines = [
        "# How soon a re-target's plan is ready",
        "",
        f"`python benchmarks/bench_retarget.py --samples {samples}` — drake {version('drake')}, "
        f"{platform.machine()}, Python {platform.python_version()}; {wall:.0f} s of wall time. "
        "Planning seconds are wall time of in-process planner calls on this 2-core machine; "
        f"latency: see the benchmark's docstring (up to {RETARGETS_AHEAD} re-targets asked ahead "
        "from the lift's end at each commitment).",
        "",
        "| cell | re-targets | plan from the lift's end, median / max [s] | plan from the "
        "pre-place, median / max [s] | lift's end [s] | carry [s] |",
        "|---|---|---|---|---|---|",
    ]
    for cell in CELLS:
        mine = [r for r in rows if r["cell"] == cell]
        lift = [s for r in mine for s in r["lift"].values()]
        place = [s for r in mine for s in r["pre-place"].values()]
        ends = [r["turns"]["lift"] for r in mine]
        carry = [r["turns"]["pre-place"] - r["turns"]["lift"] for r in mine]
        lines.append(
            f"| {cell} | {len(lift)} | {np.median(lift):.3f} / {max(lift):.3f} | "
            f"{np.median(place):.3f} / {max(place):.3f} | {min(ends):.2f}–{max(ends):.2f} | "
            f"{min(carry):.2f}–{max(carry):.2f} |"
        )
    lines += [
        "",
        "Latency over the indication delays (every re-target bet of the cell, "
        f"{samples} indication times each):",
        "",
        "| cell | interface | indicated before the lift's end | median latency [ms] | p95 "
        "[ms] | max [ms] |",
        "|---|---|---|---|---|---|",
    ]
    worst_median = 0.0
    for cell in CELLS:
        mine = [r for r in rows if r["cell"] == cell]
        for interface in INTERFACES:
            waits, early = [], []
            for row in mine:
                delay = DEFAULT_DELAYS[interface]
                times = np.array([delay.sample(rng) for _ in range(samples)])
                early.append(np.mean(times < row["turns"]["lift"]))
                for task in row["lift"]:
                    waits.append(latencies(row, task, times))
            flat = np.concatenate(waits)
            median = float(np.median(flat))
            worst_median = max(worst_median, median)
            lines.append(
                f"| {cell} | {interface} | {100 * np.mean(early):.0f} % | {1000 * median:.0f} | "
                f"{1000 * np.percentile(flat, 95):.0f} | {1000 * flat.max():.0f} |"
            )
    verdict = "met" if worst_median < 0.05 else "not met"
    lines += [
        "",
        f"Largest median latency: {1000 * worst_median:.0f} ms (target < 50 ms: {verdict}).",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000)
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = [row for cell in CELLS for row in measure(cell)]
    text = report(rows, args.samples, time.perf_counter() - start)
    atomic_write_text(REPORT, text)
    print(f"{text}\nwritten to {REPORT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
