"""The paper's Q-learning schedule against our two, over many seeds, on the flange case.

Run: python benchmarks/bench_learning.py [--seeds N]
For each Table 2 row: how often the learned policy gives the published sequence, the
minimum-effort one, another equally short one, or a longer one / none. For each schedule: how
many seeds give a policy that is minimum-effort from every non-terminal state, with episodes and
wall time. "script n/a": the policy took another, equally short route on which the scripted
deviation (e.g. F02 at step 3) is not a feasible task. Writes benchmarks/reports/learning.md.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections import Counter
from pathlib import Path

from hrc_drake.atomic import atomic_write_text
from hrc_drake.hri.operator import ScriptedOperator
from hrc_drake.progress import ProgressLine
from hrc_drake.scenario.load import table2_scenarios
from hrc_drake.tasks.decide import DecisionError, minimum_effort_violations, run_decisions
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.learn import (
    CoverageSchedule,
    ExploringStartsSchedule,
    FullSchedule,
    PaperSchedule,
    train,
)
from hrc_drake.tasks.mdp import build_mdp
from hrc_drake.tasks.policy import policy_from_choices
from hrc_drake.tasks.spec import load_spec

HERE = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--out", type=Path, default=HERE / "reports" / "learning.md")
    args = parser.parse_args()
    space = generate_states(load_spec())
    mdp = build_mdp(space)
    rows = table2_scenarios()
    lines = [
        "# Q-learning on the flange case: the paper's schedule and ours",
        "",
        f"Command: `python benchmarks/bench_learning.py --seeds {args.seeds}` "
        "(seeds 0 .. N-1; mistake probability 0.05, gamma 0.95).",
        "",
        "An *episode* starts in one state (the empty base for `paper`; the exploring start for "
        "`full`, a state-task pair, and `explore`, a state) and ends on reaching a terminal "
        "state or after 100 tasks; a *step* is one task the operator performs (undo included). "
        "Episodes and steps are counted until the schedule's own stop rule ends training; the "
        "policy judged is the greedy one at that point.",
        "",
        "`explore` (`ExploringStartsSchedule()`): each sweep starts one episode from every "
        "non-terminal state (16 on the flange case), deepest states first, opening with the "
        "state's least-tried task; then greedy with ε = 0.3 / sweep; Q starts at 2 (optimistic: "
        "the terminal reward); learning rate 1/n^0.6 per pair; stops when the greedy task of "
        "every state is unchanged for 2 sweeps (at least 3, at most 10 sweeps).",
        "",
        "`cover` (`CoverageSchedule()`, the default of `hrc-drake train`): rounds of exploring "
        "starts from every (state, task) pair of the states learning is not done with, "
        "vectorised; choices within the operator's noise raced until resolved; stops at a full "
        "sweep once 2 in a row found the greedy policy finishing from every state in an "
        "unchanged number of tasks (`hrc_drake/tasks/coverage.py`; at scale: "
        "benchmarks/reports/coverage.md).",
        "",
        "| schedule | minimum effort from every state | within 200 episodes | episodes "
        "(median / max) | steps (median) | wall time (median) |",
        "|---|---|---|---|---|---|",
        "SUMMARY",
        "",
    ]
    summary = []
    for schedule in (
        PaperSchedule(),
        FullSchedule(),
        ExploringStartsSchedule(),
        CoverageSchedule(),
    ):
        outcome = {r.table2_row: Counter() for r in rows}
        episodes, steps, walls, good, oks = [], [], [], 0, []
        bad_states = Counter()
        with ProgressLine(f"{schedule.name} schedule", "seed") as bar:
            for seed in range(args.seeds):
                result = train(mdp, schedule, seed=seed)
                policy = policy_from_choices(mdp, result.choice, schedule.name)
                episodes.append(result.episodes)
                steps.append(result.steps)
                walls.append(result.wall_time)
                violations = minimum_effort_violations(space, policy)
                good += not violations
                oks.append(not violations)
                bad_states.update(" ".join(s) or "(start)" for s in violations)
                for row in rows:
                    try:
                        states, _ = run_decisions(space, policy, ScriptedOperator(row.script))
                        names = tuple(space.name(space.index(s)) for s in states)
                    except DecisionError as err:
                        names = ("n/a",) if "not feasible" in str(err) else ()
                    if names == ("n/a",):
                        key = "script n/a"
                    elif names == row.published:
                        key = "published"
                    elif names == row.minimum_effort:
                        key = "minimum effort"
                    elif names and len(names) == len(row.minimum_effort):
                        key = "other, equally short"
                    else:
                        key = "longer or none"
                    outcome[row.table2_row][key] += 1
                bar.update(seed + 1, args.seeds)
        n = args.seeds
        within = sum(e <= 200 for e, ok in zip(episodes, oks, strict=True) if ok)
        summary.append(
            f"| {schedule.name} | {good}/{n} | {within}/{n} | "
            f"{statistics.median(episodes):.0f} / {max(episodes)} | "
            f"{statistics.median(steps):.0f} | {1e3 * statistics.median(walls):.1f} ms |"
        )
        lines += [
            f"## {schedule.name} schedule",
            "",
            f"- minimum-effort from every non-terminal state: **{good}/{n} seeds**",
            f"- episodes: median {statistics.median(episodes):.0f}, max {max(episodes)}; "
            f"steps: median {statistics.median(steps):.0f}; wall time: median "
            f"{1e3 * statistics.median(walls):.1f} ms, max {1e3 * max(walls):.1f} ms",
        ]
        if bad_states:
            worst = ", ".join(f"{s} ({c})" for s, c in bad_states.most_common(6))
            lines.append(f"- states where some seeds are not minimum-effort: {worst}")
        lines += [
            "",
            "| row | published | minimum effort | published seq. | min-effort seq. |"
            " other, equally short | longer or none | script n/a |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            c = outcome[row.table2_row]
            same = row.published == row.minimum_effort
            min_effort = "(same)" if same else f"{100 * c['minimum effort'] / n:.0f} %"
            lines.append(
                f"| {row.table2_row} | {' '.join(row.published)} | "
                f"{' '.join(row.minimum_effort)} | {100 * c['published'] / n:.0f} % | "
                f"{min_effort} | "
                f"{100 * c['other, equally short'] / n:.0f} % | "
                f"{100 * c['longer or none'] / n:.0f} % | {100 * c['script n/a'] / n:.0f} % |"
            )
        lines.append("")
    at = lines.index("SUMMARY")
    lines[at : at + 1] = summary
    lines += _other_assemblies(min(args.seeds, 20))
    atomic_write_text(args.out, "\n".join(lines))
    print("\n".join(lines))


def _other_assemblies(seeds: int) -> list[str]:
    """The explore and cover schedules on the other assemblies of models/assemblies (the full
    schedule's pair sweeps grow with the number of state-task pairs; see
    benchmarks/reports/tasks.md)."""
    lines = [
        f"## explore and cover on the other assemblies ({seeds} seeds)",
        "",
        "| assembly | states | episodes per sweep | explore: minimum effort from every state | "
        "explore: episodes (median / max) | cover: minimum effort from every state | "
        "cover: episodes (median / max) |",
        "|---|---|---|---|---|---|---|",
    ]
    for path in sorted((HERE.parent / "models" / "assemblies").glob("*.yaml")):
        space = generate_states(load_spec(path))
        if space.spec.name == "flange":
            continue
        mdp = build_mdp(space)
        starts = int(sum(mdp.edge_start[s + 1] > mdp.edge_start[s] for s in range(space.n_states)))
        cells = []
        for schedule in (ExploringStartsSchedule(), CoverageSchedule()):
            good, episodes = 0, []
            with ProgressLine(f"{schedule.name} on {path.stem}", "seed") as bar:
                for seed in range(seeds):
                    result = train(mdp, schedule, seed=seed)
                    policy = policy_from_choices(mdp, result.choice, schedule.name)
                    good += not minimum_effort_violations(space, policy)
                    episodes.append(result.episodes)
                    bar.update(seed + 1, seeds)
            cells += [f"{good}/{seeds}", f"{statistics.median(episodes):.0f} / {max(episodes)}"]
        lines.append(f"| {path.stem} | {space.n_states} | {starts} | {' | '.join(cells)} |")
    lines += [
        "",
        "On these the greedy choice of explore keeps moving between tasks of equal value, so "
        "training runs to the 10-sweep cap; the episodes are 10 sweeps of one episode per "
        "non-terminal state.",
        "",
    ]
    return lines


if __name__ == "__main__":
    sys.exit(main())
