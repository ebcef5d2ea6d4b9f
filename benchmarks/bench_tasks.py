"""Scaling of the task layer: generation, exact solve and Q-learning on growing assemblies.

Run: python benchmarks/bench_tasks.py [--quick]
Each size runs in its own process so that its peak memory (max RSS) is its own. Writes
benchmarks/reports/tasks.md. Targets: 1e6 states generated and solved in < 10 s, < 2 GB peak.
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def measure(slots: int, ovals: int, squares: int) -> dict:
    """Figures for one size, measured in this process."""
    from generated import generated_spec

    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.learn import PaperSchedule, train
    from hrc_drake.tasks.mdp import build_mdp
    from hrc_drake.tasks.solve import solve_exact, tasks_to_finish

    spec = generated_spec(slots, ovals, squares)
    t0 = time.perf_counter()
    space = generate_states(spec)
    t1 = time.perf_counter()
    mdp = build_mdp(space)
    t2 = time.perf_counter()
    solution = solve_exact(mdp)
    t3 = time.perf_counter()
    best = tasks_to_finish(space)
    t4 = time.perf_counter()
    result = train(mdp, PaperSchedule(max_episodes=400, stop_tolerance=0.0), seed=0)
    rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "size": f"{slots} slots, {ovals} F, {squares} S",
        "states": space.n_states,
        "edges": mdp.n_edges,
        "generate_s": t1 - t0,
        "mdp_s": t2 - t1,
        "solve_s": t3 - t2,
        "sweeps": solution.iterations,
        "min_effort_s": t4 - t3,
        "total_s": t3 - t0,
        "start_tasks": int(best[0]),
        "q_steps_per_s": result.steps / result.wall_time,
        "peak_mb": rss_kb / 1024,
    }


def policy_lookup_time(repeats: int = 5000) -> tuple[float, float]:
    """µs per `Policy.next_task` call over all flange states, and its ratio to a dict look-up."""
    import timeit

    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.solve import exact_policy
    from hrc_drake.tasks.spec import load_spec

    space = generate_states(load_spec())
    policy = exact_policy(space)
    states = [space.sequence(s) for s in range(space.n_states)]
    table = dict(policy.table)
    calls = repeats * len(states)
    t_policy = timeit.timeit(lambda: [policy.next_task(s) for s in states], number=repeats)
    t_dict = timeit.timeit(lambda: [table.get(s) for s in states], number=repeats)
    return 1e6 * t_policy / calls, t_policy / t_dict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=HERE / "reports" / "tasks.md")
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure(*map(int, args.one.split(",")))))
        return
    from generated import SIZES

    from hrc_drake.atomic import atomic_write_text

    sizes = SIZES[:3] if args.quick else SIZES
    rows = []
    for i, size in enumerate(sizes, 1):
        print(f"[{i}/{len(sizes)}] {size} ...", file=sys.stderr, flush=True)
        out = subprocess.run(
            [sys.executable, __file__, "--one", ",".join(map(str, size))],
            check=True,
            capture_output=True,
            text=True,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    lines = [
        "# Task layer scaling",
        "",
        f"Machine: {platform.machine()}, Python {platform.python_version()}."
        " Command: `python benchmarks/bench_tasks.py`. Each size in its own process.",
        "",
        "| assembly | states | edges | generate [s] | MDP [s] | exact solve [s] | VI sweeps |"
        " generate+MDP+solve [s] | Q-learning steps/s | peak RSS [MB] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['size']} | {r['states']:,} | {r['edges']:,} | {r['generate_s']:.3f} | "
            f"{r['mdp_s']:.3f} | {r['solve_s']:.3f} | {r['sweeps']} | {r['total_s']:.2f} | "
            f"{r['q_steps_per_s']:,.0f} | {r['peak_mb']:.0f} |"
        )
    big = [r for r in rows if r["states"] >= 1_000_000]
    if big:
        r = big[0]
        verdict = "met" if r["total_s"] < 10 and r["peak_mb"] < 2048 else "NOT met"
        lines += [
            "",
            f"Target (1e6 states: generate + solve < 10 s, < 2 GB): {verdict} — "
            f"{r['states']:,} states in {r['total_s']:.2f} s, {r['peak_mb']:.0f} MB.",
        ]
    per_call, ratio = policy_lookup_time()
    lines += [
        "",
        f"`Policy.next_task` on the flange case: {per_call:.2f} µs per call "
        f"({ratio:.1f}× a bare dict look-up in the same run; target well under 50 µs).",
    ]
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
