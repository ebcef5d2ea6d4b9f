"""The cell's speed against baseline commits, side by side -> benchmarks/reports/speed.md.

Runs `hrc-drake simulate --json` at full settings on the cases of `CASES` (row 5 with the
default sensors; `shared-desk` with `sensors: realistic`) with the code of each baseline commit
(default 2ccda38, the code issue 51 was filed on, unpacked by `git archive` into a temporary
directory: the repository's state is not touched) and with the working tree, alternating the
sides run by run, `--rounds` times each, one run at a time. Per case and baseline it reports
every run's real-time factor (simulated / wall seconds of the run's loop, `real_time_factor` in
the JSON), the best of each side and their ratio, and whether both sides visited the same states
in the same simulated time (to 1e-6 s; an older baseline may not, and is then compared per
simulated second). Wall times depend on the machine and its load: compare the ratio, measured
on a quiet machine.

Usage: ``python benchmarks/bench_speed.py [--baseline 2ccda38 ...] [--case NAME ...]
[--rounds 2] [--lean] [--tree PATH] [--out benchmarks/reports/speed.md]`` (a baseline or a case
repeated adds one; a baseline older than `sensors:` runs only ``--case row5-forces-5``; with
``--lean``, 0.5 s holds, a quick look: the report is printed, not written; ``--tree``: another
checkout to time instead of the working tree).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "2ccda38"
TREE = "working tree"
# name -> (scenario, --scenario-text or None)
CASES = {
    "row5-forces-5": ("row5-forces-5", None),
    "shared-desk, realistic sensors": ("shared-desk", "{sensors: realistic}"),
}


def unpack(commit: str, into: Path) -> Path:
    """The tree of `commit` unpacked under `into` (by `git archive`; no git state changes)."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", commit], check=True, capture_output=True
    ).stdout
    into.mkdir(parents=True, exist_ok=True)
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into


def code_of(tree: Path) -> str:
    """Where `import hrc_drake` resolves with `tree` first on the path (checked, not assumed)."""
    out = subprocess.run(
        [sys.executable, "-c", "import hrc_drake; print(hrc_drake.__file__)"],
        env={**os.environ, "PYTHONPATH": str(tree)},
        cwd=tree,  # `python -c` and `-m` put the current directory first on the path
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    if not out.startswith(str(tree)):
        raise SystemExit(f"the code under {tree} is not what runs ({out}): check PYTHONPATH")
    return out


def simulate(tree: Path, scenario: str, text: str | None, lean: bool) -> dict:
    """One run's JSON with the code of `tree`."""
    args = [sys.executable, "-m", "hrc_drake.cli", "simulate", "--scenario", scenario, "--json"]
    args += ["--scenario-text", text] if text else []
    args += ["--lean"] if lean else []
    done = subprocess.run(
        args, env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, capture_output=True, text=True
    )
    if done.returncode != 0:
        raise SystemExit(f"{scenario} under {tree} failed: {done.stderr.strip()[-300:]}")
    return json.loads(done.stdout)


def same_run(a: dict, b: dict) -> bool:
    """Whether two runs visited the same states in the same simulated time (to 1e-6 s)."""
    return a["states"] == b["states"] and abs(a["sim_time"] - b["sim_time"]) <= 1e-6


def measure(trees: dict[str, Path], cases: list[str], rounds: int, lean: bool) -> dict:
    """case -> side -> runs, the sides alternating run by run."""
    runs: dict[str, dict[str, list]] = {case: {side: [] for side in trees} for case in cases}
    for k in range(rounds):
        for case in cases:
            scenario, text = CASES[case]
            for side, tree in trees.items():
                run = simulate(tree, scenario, text, lean)
                runs[case][side].append(run)
                rtf = run["real_time_factor"]
                print(f"round {k + 1}: {case}: {side}: {rtf:.3f}", file=sys.stderr, flush=True)
    return runs


def report(runs: dict[str, dict[str, list]], command: str, tree: Path) -> str:
    """The report's Markdown: per case, each baseline against the working tree."""
    lines = [
        "# Speed: the cell against its baselines, side by side",
        "",
        f"`{command}` on {platform.node()} ({os.cpu_count()} cores; load average before the "
        f"last run {os.getloadavg()[0]:.2f}). Real-time factor = simulated / wall seconds of "
        "the run's loop; the sides alternate run by run; best of each. Working tree: "
        f"{tree}. A baseline whose runs differ from the tree's (states or simulated time) is "
        "compared per simulated second.",
        "",
        "| case | baseline | baseline runs | working tree runs | best baseline | "
        "best working tree | ratio | same states and time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for case, sides in runs.items():
        new = sides[TREE]
        best_new = max(r["real_time_factor"] for r in new)
        for side, base in sides.items():
            if side == TREE:
                continue
            best_base = max(r["real_time_factor"] for r in base)
            same = all(same_run(base[0], r) for r in base + new)
            listed = [", ".join(f"{r['real_time_factor']:.3f}" for r in x) for x in (base, new)]
            lines.append(
                f"| {case} | {side} | {listed[0]} | {listed[1]} | {best_base:.3f} | "
                f"{best_new:.3f} | {best_new / best_base:.3f} | {'yes' if same else 'no'} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the comparison and write (or, with --lean, print) its report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline",
        action="append",
        help=f"a baseline commit; repeat for several (default {BASELINE})",
    )
    parser.add_argument(
        "--case", action="append", choices=sorted(CASES), help="a case; repeat (default: all)"
    )
    parser.add_argument("--rounds", type=int, default=2, help="runs of each side per case")
    parser.add_argument("--lean", action="store_true", help="0.5 s holds; print the report")
    parser.add_argument("--tree", default=str(ROOT), help="the checkout to time (default: this)")
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "reports" / "speed.md"))
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be a whole number >= 1, not {args.rounds}")
    baselines = args.baseline or [BASELINE]
    cases = args.case or list(CASES)
    command = "python benchmarks/bench_speed.py " + " ".join(
        [*(f"--baseline {b}" for b in baselines), *(f"--case '{c}'" for c in args.case or [])]
        + [f"--rounds {args.rounds}"]
        + (["--lean"] if args.lean else [])
    )
    with tempfile.TemporaryDirectory(prefix="bench_speed_") as tmp:
        trees = {b: unpack(b, Path(tmp) / b) for b in baselines}
        trees[TREE] = Path(args.tree)
        for side, tree in trees.items():
            print(f"{side}: {code_of(tree)}", file=sys.stderr)
        runs = measure(trees, cases, args.rounds, args.lean)
        text = report(runs, command, trees[TREE])
    if args.lean:
        print(text)
        return 0
    from hrc_drake.atomic import atomic_write_text

    print(f"wrote {atomic_write_text(args.out, text)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
