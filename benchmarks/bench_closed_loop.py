"""Closed-loop cell: real-time factor of a full assembly, the nine Table 2 rows, time per row.

Run: python benchmarks/bench_closed_loop.py [--rows N]
1. Full settings (5 s bolting holds, 0.25 m/s TCP): every Table 2 row, with the simulated
   assembly time per row and the real-time factor. Plans are made once and cached, so the first
   rows pay for planning; the row-1 assembly is then run again with every plan cached, which is
   the physics-only real-time factor (target >= 1).
2. Lean settings (what pytest runs): wall time of the nine-row suite.
Writes benchmarks/reports/closed_loop.md.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.run.run import run_scenario
from hrc_drake.cell.scenario import LEAN
from hrc_drake.scenario.load import table2_scenarios

HERE = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rows", type=int, default=9)
    parser.add_argument("--out", type=Path, default=HERE / "reports" / "closed_loop.md")
    args = parser.parse_args()
    rows = table2_scenarios()[: args.rows]
    lines = [
        "# Closed-loop cell",
        "",
        f"Command: `python benchmarks/bench_closed_loop.py --rows {args.rows}`. The plans come "
        "from the runs' planning worker (a process beside the controller, one per set of "
        "options).",
        "",
        "## Full settings (5 s bolting holds, TCP <= 0.25 m/s), every Table 2 row",
        "",
        "| row | states visited | ok | tasks | simulated [s] | wall [s] | RTF (incl. "
        "planning) | collisions |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        print(f"full: {row.name} ...", flush=True)
        r = run_scenario(row.name)
        ok = r.done and r.names == list(row.minimum_effort)
        lines.append(
            f"| {row.table2_row} | {' '.join(r.names)} | {'yes' if ok else 'NO'} | "
            f"{len(r.tasks)} | {r.sim_time:.1f} | {r.wall_time:.1f} | "
            f"{r.sim_time / r.wall_time:.2f} | {len(r.collisions)} |"
        )
    again = run_scenario(rows[0].name)
    lines += [
        "",
        f"Row {rows[0].table2_row} again with every plan cached (physics and control "
        f"only): {again.sim_time:.1f} s simulated in {again.wall_time:.1f} s, real-time "
        f"factor **{again.sim_time / again.wall_time:.2f}**.",
        "",
    ]
    start = time.perf_counter()
    sims = []
    for row in rows:
        print(f"lean: {row.name} ...", flush=True)
        sims.append(run_scenario(row.name, scenario_text=LEAN).sim_time)
    wall = time.perf_counter() - start
    lines += [
        "## Lean settings (0.5 s holds), as in pytest",
        "",
        f"{len(rows)}-row suite: {sum(sims):.1f} s simulated in {wall:.1f} s wall "
        "(plans cached from the full runs above only where the options match: none, so "
        "this includes planning).",
        "",
    ]
    atomic_write_text(args.out, "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
