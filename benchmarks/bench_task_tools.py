"""The task layer's tools at scale: listings, the exact solve, the policy check and the refusal
of a looping policy, on generated specs of 29,267 and 820,427 states.

Run: python benchmarks/bench_task_tools.py [--quick] [--before DIR]
Every figure is one `hrc-drake` command in its own process, timed by `/usr/bin/time` (wall and
CPU seconds, peak resident memory), stdout sent to /dev/null. `--before DIR`: also run each
command with an older source tree first on the path (`git archive COMMIT | tar -x -C DIR`),
right after the current one, so that both see the same machine load. `--quick`: the smaller
spec only. Writes benchmarks/reports/task_tools.md.
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

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
TIME = "/usr/bin/time"
sys.path.insert(0, str(HERE))

from generated import two_host_data  # noqa: E402

SIZES = {"six parts, 8 slots": (8, 2), "seven parts, 10 slots": (10, 3)}


def timed(argv: list[str], tree: Path | None = None, allowed=(0, 1, 2)) -> dict:
    """Wall and CPU seconds, peak KB, exit status and stderr of `hrc-drake argv` (stdout
    discarded), with `tree` first on the Python path when given (run from the temporary
    folder: `python -m` puts the working folder before PYTHONPATH)."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    if tree is not None:
        env["PYTHONPATH"] = str(tree.resolve())
    with tempfile.NamedTemporaryFile("r", suffix=".time") as out:
        cmd = [TIME, "-f", "%e %U %S %M", "-o", out.name, sys.executable, "-m", "hrc_drake.cli"]
        done = subprocess.run(
            [*cmd, *argv],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            cwd=tempfile.gettempdir(),
        )
        if done.returncode not in allowed:
            raise RuntimeError(f"hrc-drake {' '.join(argv)} failed: {done.stderr.strip()}")
        wall, user, system, kb = out.read().split()[-4:]
    return {
        "s": float(wall),
        "cpu": float(user) + float(system),
        "kb": int(kb),
        "exit": done.returncode,
        "stderr": done.stderr.strip(),
    }


def looping_policy(spec: Path, exact: Path, out: Path, count: int = 2000) -> None:
    """The exact policy with `count` seeded non-start states switched to undo (in a process of
    its own: not part of any figure)."""
    code = f"""
import dataclasses, random
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.policy import load_policy, save_policy
from hrc_drake.tasks.spec import load_spec
space = generate_states(load_spec({str(spec)!r}))
policy = load_policy({str(exact)!r}, space)
table = dict(policy.table)
for seq in random.Random(0).sample(sorted(k for k in table if k), {count}):
    table[seq] = "undo"
save_policy(dataclasses.replace(policy, table=table, method="edited"), {str(out)!r})
"""
    subprocess.run([sys.executable, "-c", code], check=True)


def check_json(spec: Path, policy: Path) -> dict:
    """The `check-policy --json` summary (its state list dropped)."""
    argv = ["check-policy", "--assembly", str(spec), "--policy", str(policy), "--json"]
    done = subprocess.run(
        [sys.executable, "-m", "hrc_drake.cli", *argv], capture_output=True, text=True
    )
    report = json.loads(done.stdout)
    report.pop("not_minimum_effort_states")
    return report


def measure(label: str, slots: int, on_base: int, work: Path, before: Path | None) -> list[dict]:
    """Figures for one spec."""
    spec = work / f"two-host-{slots}.yaml"
    spec.write_text(yaml.safe_dump(two_host_data(slots, on_base)))
    exact, loop = work / f"exact-{slots}.json", work / f"loop-{slots}.json"
    a = ["--assembly", str(spec)]
    rows = []

    def row(name, argv, note="", old=True):
        now = timed(argv)
        was = timed(argv, before) if before is not None and old else None
        rows.append({"spec": label, "command": name, "now": now, "was": was, "note": note})
        then = "" if was is None else f" (before: {was['s']:.2f} s, {was['kb'] / 1024:.0f} MB)"
        print(f"  {name}: {now['s']:.2f} s, {now['kb'] / 1024:.0f} MB{then}", file=sys.stderr)
        return now

    row("states --json", ["states", "--json", *a])
    row("policy --json", ["policy", "--json", *a])
    row("solve --out", ["solve", *a, "--out", str(work / "scratch.json"), "--force"])
    timed(["solve", *a, "--out", str(exact)])  # the file the rows below read
    row("policy --json --policy EXACT", ["policy", "--json", *a, "--policy", str(exact)])
    row("check-policy --policy EXACT", ["check-policy", *a, "--policy", str(exact)], old=False)
    looping_policy(spec, exact, loop)
    report = check_json(spec, loop)
    note = f"{report['loops']:,} looping, {report['not_minimum_effort']:,} not minimum-effort"
    row("check-policy --policy LOOPING", ["check-policy", *a, "--policy", str(loop)], note, False)
    now = row("react --policy LOOPING", ["react", *a, "--policy", str(loop)])
    rows[-1]["note"] = "refused: …" + now["stderr"].split(".json", 1)[-1].split(" (e.g.")[0]
    was = rows[-1]["was"]
    if was is not None:
        said = was["stderr"].splitlines()[-1][:70] + "…" if was["stderr"] else "no error"
        rows[-1]["note"] += f"; before: exit {was['exit']}, {said}"
    if slots <= 8:  # today's `explore` schedule: ~10 s here, 331 s on the larger spec
        q = work / f"explore-{slots}.json"
        argv = ["train", *a, "--schedule", "explore", "--seed", "0", "--out", str(q)]
        row("train --schedule explore --seed 0", argv, old=False)
        report = check_json(spec, q)
        note = (
            f"{report['loops']:,} looping, {report['not_minimum_effort']:,} not minimum-effort "
            f"of {report['non_terminal']:,}"
        )
        row("check-policy --policy EXPLORE", ["check-policy", *a, "--policy", str(q)], note, False)
    return rows


def _figures(r: dict | None) -> str:
    if r is None:
        return "– | – | –"
    return f"{r['s']:.2f} | {r['cpu']:.2f} | {r['kb'] / 1024:.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="the smaller spec only")
    parser.add_argument("--before", type=Path, default=None, help="an older source tree")
    parser.add_argument("--out", type=Path, default=HERE / "reports" / "task_tools.md")
    args = parser.parse_args()
    sys.path.insert(0, str(REPO))
    from hrc_drake.atomic import atomic_write_text

    sizes = list(SIZES.items())[:1] if args.quick else list(SIZES.items())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, (slots, on_base) in sizes:
            print(f"{label} ...", file=sys.stderr, flush=True)
            rows += measure(label, slots, on_base, Path(tmp), args.before)
    before = f"`--before {args.before}`" if args.before else "not measured"
    lines = [
        "# Task tools at scale: listings, solve, the policy check",
        "",
        f"Machine: {platform.machine()}, Python {platform.python_version()}, two cores shared "
        "with other work (wall times vary by tens of percent; CPU = user + system seconds). "
        "Command: `python benchmarks/bench_task_tools.py --before DIR`, DIR holding the tree "
        "before this change (`git archive 2ccda38 | tar -x -C DIR`), each of its commands run "
        f"right after the current one ({before}). Each figure is one `hrc-drake` command in "
        "its own process (`/usr/bin/time`), stdout to /dev/null. Specs: two host flanges "
        "completed first, oval flanges on the base (the script writes them). EXACT: the file "
        "`solve --out` wrote; LOOPING: it with 2,000 seeded states switched to undo; EXPLORE: "
        "the file `train --schedule explore --seed 0` wrote.",
        "",
        "| spec | command | wall [s] | CPU [s] | peak RSS [MB] | before: wall [s] | CPU [s] |"
        " peak RSS [MB] | exit | note |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['spec']} | `{r['command']}` | {_figures(r['now'])} | {_figures(r['was'])} | "
            f"{r['now']['exit']} | {r['note']} |"
        )
    lines += [
        "",
        "`check-policy` exits 1 when the policy loops from some state; `react` (as `simulate`) "
        "refuses such a file with exit status 2 before anything else is done. Before this "
        "change there was no `check-policy`, and `react` ran a looping file (exit 0 when the run "
        "from the start does not meet a loop).",
    ]
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
