"""Minimax-Q against an operator with K mistakes, scored against the exact min-max.

Run: python benchmarks/bench_adversary.py [--large]
For the flange case, the 4-slot spec and a spec of six parts on eight slots with two host
flanges (29,267 states; `--large` adds seven parts on ten slots, 820,427 states, K = 1 only),
K = 1 and 2: the learner's rounds, episodes, steps and wall time, the exact min-max solve's
time, and the share of the non-terminal (state, mistakes left) from which the learned policy's
worst case (the operator's exact best response) equals the min-max one. Each row runs in its
own process so that its peak memory (max RSS) is its own. Writes
benchmarks/reports/adversary.md.
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
REPO = HERE.parent
sys.path.insert(0, str(HERE))

from generated import two_host_spec  # noqa: E402

SPECS = {
    "flange": lambda: _load(None),
    "four-slot": lambda: _load(REPO / "models" / "assemblies" / "four-slot.yaml"),
    "six parts, 8 slots": lambda: two_host_spec(8, 2),
    "seven parts, 10 slots": lambda: two_host_spec(10, 3),
}


def _load(path):
    from hrc_drake.tasks.spec import load_spec

    return load_spec(path)


def measure(name: str, budget: int) -> dict:
    """One row, measured in this process."""
    import numpy as np

    from hrc_drake.tasks.adversary import (
        adversary_game,
        agreement,
        policy_worst_case,
        solve_minimax,
        train_minimax,
    )
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.mdp import build_mdp
    from hrc_drake.tasks.solve import solve_exact

    space = generate_states(SPECS[name]())
    game = adversary_game(space, budget)
    cpu = time.process_time()
    result = train_minimax(game, seed=0)
    cpu = time.process_time() - cpu
    exact = solve_minimax(game)
    t0 = time.perf_counter()
    learned = agreement(exact, policy_worst_case(game, result.choice))
    best_response_s = time.perf_counter() - t0
    effort = agreement(exact, policy_worst_case(game, solve_exact(build_mdp(space)).choice))
    return {
        "spec": name,
        "states": space.n_states,
        "budget": budget,
        "augmented": learned.states,
        "rounds": result.rounds,
        "converged": result.converged,
        "episodes": result.episodes,
        "steps": result.steps,
        "learn_s": result.wall_time,
        "learn_cpu_s": cpu,
        "exact_s": exact.wall_time,
        "best_response_s": best_response_s,
        "equal": learned.equal,
        "value_gap": float(np.max(np.abs(result.values - exact.values))),
        "start": int(exact.tasks[budget, 0]),
        "effort_longer": effort.longer,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--large", action="store_true", help="add 820,427 states (K = 1)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, default=HERE / "reports" / "adversary.md")
    args = parser.parse_args()
    if args.one:
        name, budget = args.one.rsplit(":", 1)
        print(json.dumps(measure(name, int(budget))))
        return
    from hrc_drake.atomic import atomic_write_text

    runs = [(name, k) for name in list(SPECS)[:3] for k in (1, 2)]
    if args.large:
        runs.append(("seven parts, 10 slots", 1))
    rows = []
    for i, (name, budget) in enumerate(runs, 1):
        print(f"[{i}/{len(runs)}] {name}, K = {budget} ...", file=sys.stderr, flush=True)
        out = subprocess.run(
            [sys.executable, __file__, "--one", f"{name}:{budget}"],
            check=True,
            capture_output=True,
            text=True,
        )
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    command = "python benchmarks/bench_adversary.py" + (" --large" if args.large else "")
    lines = [
        "# Minimax-Q against an operator with K mistakes, against the exact min-max",
        "",
        f"Machine: {platform.machine()}, Python {platform.python_version()}, 2 cores shared. "
        f"Command: `{command}`. Seed 0, gamma 0.95, `MinimaxSchedule()`; each row in its own "
        "process. The machine is shared with other work: wall time varies with the load, the "
        "learner's CPU time (its process) less.",
        "",
        "*Augmented*: non-terminal (state, mistakes left) pairs. *Equal*: those from which the "
        "learned greedy policy's worst case (the operator's exact best response, in tasks) is "
        "the exact min-max's. *Value gap*: largest difference between the learner's values and "
        "the exact game values (paper's reward). *Min-effort longer*: pairs from which the "
        "expected-value minimum-effort policy (5 % mistakes, the `exact` decider) takes longer "
        "than min-max at worst. An *episode* starts at one (state, mistakes left, proposal); a "
        "*step* is one task.",
        "",
        "| spec | states | K | augmented | rounds | episodes | steps | learn: wall [s] |"
        " CPU [s] | exact [s] |"
        " equal | value gap | worst case from start | min-effort longer | peak RSS [MB] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        settled = "" if r["converged"] else " (not settled)"
        lines.append(
            f"| {r['spec']} | {r['states']:,} | {r['budget']} | {r['augmented']:,} | "
            f"{r['rounds']}{settled} | {r['episodes']:,} | {r['steps']:,} | {r['learn_s']:.2f} | "
            f"{r['learn_cpu_s']:.2f} | "
            f"{r['exact_s']:.2f} | {r['equal']:,}/{r['augmented']:,} | {r['value_gap']:.2g} | "
            f"{r['start']} | {r['effort_longer']:,} | {r['peak_mb']:.0f} |"
        )
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
