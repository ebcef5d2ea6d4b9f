"""Reactive against predictive separation -> benchmarks/reports/shared_desk.md.

Section 1: the `shared-desk` scenario (the operator points at the target seat and fetches each
part's bolts and nuts from bins beside the robot's carry path), every operator population, both
interaction modes, the same operator seeds (each seed its own person: `body.spread`), once with
monitoring alone (`reactive`) and once with the robot timing its moves around its forecast of the
operator (`predictive`). Per run: the assembly's simulated seconds, `ssm_delay` (what slowing and
stopping added), the planned waits, least separation and margin, violations (by the run's own
check, `hrc_drake.cell.run.safety_check`), body contacts, what the check finds beyond ISO/TS
15066 (steps faster than the body region permits, contacts beyond its force) and the seconds in
each of the station's safety modes (normal, reduced, stopped).

Section 2: the regression cells — Table 2's nine rows and the 4-slot and 5-slot cells — in both
separation modes: the states of `react`, terminal, collisions, violations, body contacts.

Section 3: the bound of a perfect forecast. Waiting for the indication, with the operator exactly
the person the controller assumes (`body.spread: 0`) and a forecast that keeps no timing spread
(`safety.forecast_spread: 0`), the predictive robot knows where the hand will be; monitoring
alone against it, on the same seeds.

Full settings (5 s holds, TCP <= 0.25 m/s, body and monitor on). Usage:
``python benchmarks/bench_shared_desk.py [--workers 2] [--seeds 2] [--lean] [--no-regression]
[--no-bound]`` (with ``--lean`` the report is printed, not written).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

from cell_pool import error_lines, pooled_loop, publish, run_pool

POPULATIONS = ("follows", "habitual", "mistake-prone", "change-of-mind")
INTERACTIONS = ("anticipate", "wait")
SEPARATIONS = ("reactive", "predictive")
REGRESSION = {
    **{
        f"flange row {k}": (name, "")
        for k, name in enumerate(
            (
                "row1-optimal",
                "row2-forces-2",
                "row3-forces-3",
                "row4-forces-4",
                "row5-forces-5",
                "row6-forces-6",
                "row7-forces-9",
                "row8-forces-4-then-8",
                "row9-forces-5-then-14",
            ),
            1,
        )
    },
    "four-slot": (None, "{assembly: four-slot, name: four-slot}"),
    "five-slot": (None, "{assembly: five-slot, name: five-slot}"),
}
REPORT = Path(__file__).parent / "reports" / "shared_desk.md"


def scenario_of(job: tuple) -> object:
    """The scenario of a job: ("desk", population, interaction, seed, separation, lean),
    ("bound", population, seed, separation, lean) or ("regression", cell, separation, lean)."""
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    if job[0] == "bound":
        _, population, seed, separation, lean = job
        texts = [
            f"{{operator: {{model: {population}, seed: {seed}}}, interaction: {{mode: wait}}, "
            f"body: {{spread: 0.0}}, safety: {{separation: {separation}, forecast_spread: 0.0}}}}"
        ]
        name = "shared-desk"
    elif job[0] == "desk":
        _, population, interaction, seed, separation, lean = job
        texts = [
            f"{{operator: {{model: {population}, seed: {seed}}}, "
            f"interaction: {{mode: {interaction}}}, safety: {{separation: {separation}}}}}"
        ]
        name = "shared-desk"
    else:
        _, cell, separation, lean = job
        name, text = REGRESSION[cell]
        texts = [t for t in (text, f"{{safety: {{separation: {separation}}}}}") if t]
    if lean:
        texts.append(LEAN)
    return load_cell_scenario(name, texts)


def one_run(job: tuple) -> dict:
    """One closed-loop run of a job: its figures."""
    from hrc_drake.cell.run.run import scenario_policy
    from hrc_drake.tasks.decide import run_decisions
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    scenario = scenario_of(job)
    space = generate_states(load_spec(scenario.assembly_path))
    react, _ = run_decisions(
        space, scenario_policy(scenario, space), scenario.operator_for(space).operator
    )
    result = pooled_loop(scenario, scenario.assembly).run()
    safety, function = result.safety, result.safety_function
    return {
        "job": job,
        "terminal": result.done,
        "react": [list(s) for s in react] == [list(s) for s in result.states],
        "seconds": result.sim_time,
        "ssm_delay": safety.ssm_delay,
        "waited": result.waited,
        "replans": result.replans,
        "min_separation": safety.min_separation,
        "min_margin": safety.min_margin,
        # The run's own check (`hrc_drake.cell.run.safety_check`); the monitor's count beside.
        "violations": result.safety_check.violations,
        "monitor_violations": safety.violations,
        "body_contacts": result.safety_check.body_contacts,
        # Judged by ISO/TS 15066 Annex A: steps inside S_p faster than the region permits,
        # contacts beyond its force; the station's function: seconds reduced and stopped.
        "beyond": result.safety_check.beyond_permissible,
        "contacts_beyond": result.safety_check.contacts_beyond,
        "reduced": function.reduced_time if function is not None else 0.0,
        "stopped": function.stopped_time if function is not None else 0.0,
        "collisions": len(result.collisions),
        "error": result.error,
        "robot_late": robot_late(scenario, result) if job[0] != "regression" else 0.0,
    }


def robot_late(scenario, result) -> float:
    """Seconds per held task the robot put the part in place after the operator's hands were
    free of the fetch (0 where it was there first): how much of the assembly the robot's own
    motion, and what slows it, decides."""
    from hrc_drake.cell.ports import OperatorActivity
    from hrc_drake.cell.scenario import cell_design
    from hrc_drake.cell.station.build import body_script_of
    from hrc_drake.motion.scene import load_cell_frames
    from hrc_drake.tasks.spec import load_spec

    # The simulated operator's own script: its person, its desk, its end of the fetch.
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    script = body_script_of(scenario, load_cell_frames(design))
    late = []
    for task in result.tasks:
        if task.held_at is not None and task.indicated_at is not None:
            answered = OperatorActivity(
                answered_step=task.step, answered_at=task.indicated_at, answered_task=task.indicated
            )
            late.append(max(0.0, task.held_at - script.busy_until(answered)))
    return statistics.fmean(late) if late else 0.0


def _mean(runs: list[dict], key: str) -> float:
    return statistics.fmean(r[key] for r in runs)


def desk_rows(runs: list[dict]) -> list[str]:
    """Per population and interaction: reactive and predictive side by side (means over seeds)."""
    lines = [
        "| population | interaction | time reactive [s] | time predictive [s] | predictive / "
        "reactive | ssm_delay reactive [s] (% of time) | ssm_delay predictive [s] | planned "
        "wait [s] | robot late r / p [s/task] | least sep. r / p [m] | least margin r / p [m] "
        "| violations r / p | body contacts r / p | beyond ISO/TS 15066 r / p | normal / "
        "reduced / stopped r [s] | normal / reduced / stopped p [s] | terminal, react |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for population in POPULATIONS:
        for interaction in INTERACTIONS:
            pair = {
                s: [
                    r
                    for r in runs
                    if r["job"][1:3] == (population, interaction) and r["job"][4] == s
                ]
                for s in SEPARATIONS
            }
            re, pr = pair["reactive"], pair["predictive"]
            if not re or not pr:
                continue
            t_r, t_p = _mean(re, "seconds"), _mean(pr, "seconds")
            d_r, d_p = _mean(re, "ssm_delay"), _mean(pr, "ssm_delay")
            share = 100 * d_r / max(t_r - d_r, 1e-9)
            ok = all(r["terminal"] and r["react"] for r in re + pr)
            lines.append(
                f"| {population} | {interaction} | {t_r:.2f} | {t_p:.2f} | {t_p / t_r:.3f} | "
                f"{d_r:.2f} ({share:.1f} %) | {d_p:.2f} | {_mean(pr, 'waited'):.2f} | "
                f"{_mean(re, 'robot_late'):.2f} / {_mean(pr, 'robot_late'):.2f} | "
                f"{min(r['min_separation'] for r in re):.3f} / "
                f"{min(r['min_separation'] for r in pr):.3f} | "
                f"{min(r['min_margin'] for r in re):.3f} / {min(r['min_margin'] for r in pr):.3f} "
                f"| {sum(r['violations'] for r in re)} / {sum(r['violations'] for r in pr)} | "
                f"{sum(r['body_contacts'] for r in re)} / {sum(r['body_contacts'] for r in pr)} "
                f"| {_beyond(re)} / {_beyond(pr)} | {_modes(re)} | {_modes(pr)} "
                f"| {'yes' if ok else 'NO'} |"
            )
    return lines


def _beyond(runs: list[dict]) -> int:
    """Steps beyond the permissible speed and contacts beyond the permissible force, summed."""
    return sum(r["beyond"] + r["contacts_beyond"] for r in runs)


def _modes(runs: list[dict]) -> str:
    """Mean seconds in the station's safety modes: normal, reduced, stopped."""
    reduced, stopped = _mean(runs, "reduced"), _mean(runs, "stopped")
    return f"{_mean(runs, 'seconds') - reduced - stopped:.1f} / {reduced:.1f} / {stopped:.1f}"


def regression_rows(runs: list[dict]) -> list[str]:
    """Per regression cell and separation mode."""
    lines = [
        "| cell | separation | states of react | terminal | time [s] | ssm_delay [s] | "
        "collisions | violations | body contacts |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        _, cell, separation, _ = r["job"]
        lines.append(
            f"| {cell} | {separation} | {'yes' if r['react'] else 'NO'} | "
            f"{'yes' if r['terminal'] else 'NO'} | {r['seconds']:.2f} | {r['ssm_delay']:.2f} | "
            f"{r['collisions']} | {r['violations']} | {r['body_contacts']} |"
        )
    return lines


def bound_rows(runs: list[dict]) -> list[str]:
    """Per population: monitoring alone against a perfect forecast (means over seeds)."""
    lines = [
        "| population | time reactive [s] | time exact forecast [s] | exact / reactive | "
        "ssm_delay r / p [s] | robot late r / p [s/task] | least margin r / p [m] | "
        "violations r / p | terminal, react |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for population in POPULATIONS:
        re = [r for r in runs if r["job"][1] == population and r["job"][3] == "reactive"]
        pr = [r for r in runs if r["job"][1] == population and r["job"][3] == "predictive"]
        if not re or not pr:
            continue
        t_r, t_p = _mean(re, "seconds"), _mean(pr, "seconds")
        ok = all(r["terminal"] and r["react"] for r in re + pr)
        lines.append(
            f"| {population} | {t_r:.2f} | {t_p:.2f} | {t_p / t_r:.3f} | "
            f"{_mean(re, 'ssm_delay'):.2f} / {_mean(pr, 'ssm_delay'):.2f} | "
            f"{_mean(re, 'robot_late'):.2f} / {_mean(pr, 'robot_late'):.2f} | "
            f"{min(r['min_margin'] for r in re):.3f} / {min(r['min_margin'] for r in pr):.3f} | "
            f"{sum(r['violations'] for r in re)} / {sum(r['violations'] for r in pr)} | "
            f"{'yes' if ok else 'NO'} |"
        )
    return lines


def report(runs: list[dict], args, wall: float) -> str:
    """The markdown report."""
    desk = [r for r in runs if r["job"][0] == "desk"]
    regression = [r for r in runs if r["job"][0] == "regression"]
    bound = [r for r in runs if r["job"][0] == "bound"]
    totals = {s: [r for r in desk if r["job"][4] == s] for s in SEPARATIONS}
    lines = [
        "# Reactive and predictive separation on a shared desk",
        "",
        f"`python benchmarks/bench_shared_desk.py --workers {args.workers} --seeds {args.seeds}"
        f"{' --lean' if args.lean else ''}"
        f"{' --no-regression' if getattr(args, 'no_regression', False) else ''}"
        f"{' --no-bound' if getattr(args, 'no_bound', False) else ''}`: "
        f"{len(runs)} runs in {wall / 60:.1f} min on "
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()}.",
        "",
        f"## 1. `shared-desk`: every population, both interaction modes, seeds 0..{args.seeds - 1}",
        "",
        *desk_rows(desk),
        "",
    ]
    if totals["reactive"] and totals["predictive"]:
        t_r, t_p = _mean(totals["reactive"], "seconds"), _mean(totals["predictive"], "seconds")
        d_r, d_p = _mean(totals["reactive"], "ssm_delay"), _mean(totals["predictive"], "ssm_delay")
        lines += [
            f"All {len(desk)} runs: mean time reactive {t_r:.2f} s, predictive {t_p:.2f} s "
            f"(ratio {t_p / t_r:.3f}); mean ssm_delay reactive {d_r:.2f} s "
            f"({100 * d_r / max(t_r - d_r, 1e-9):.1f} % of the time without it), predictive "
            f"{d_p:.2f} s; violations reactive "
            f"{sum(r['violations'] for r in totals['reactive'])}, predictive "
            f"{sum(r['violations'] for r in totals['predictive'])}; body contacts "
            f"{sum(r['body_contacts'] for r in desk)}; collisions "
            f"{sum(r['collisions'] for r in desk)}. The robot put the part in place after the "
            f"operator's hands were free by {_mean(totals['reactive'], 'robot_late'):.2f} s a "
            f"task reactive, {_mean(totals['predictive'], 'robot_late'):.2f} s predictive.",
            "",
        ]
    if regression:
        lines += [
            "## 2. Regression cells in both separation modes",
            "",
            *regression_rows(regression),
            "",
        ]
    if bound:
        re = [r for r in bound if r["job"][3] == "reactive"]
        pr = [r for r in bound if r["job"][3] == "predictive"]
        lines += [
            "## 3. The bound of a perfect forecast (waiting for the indication)",
            "",
            "The operator is the person the controller assumes (`body.spread: 0`) and the "
            "forecast keeps no timing spread (`safety.forecast_spread: 0`): after the "
            "indication the predictive robot knows where the hand will be.",
            "",
            *bound_rows(bound),
            "",
            f"All {len(bound)} runs: mean time reactive {_mean(re, 'seconds'):.2f} s, exact "
            f"forecast {_mean(pr, 'seconds'):.2f} s (ratio "
            f"{_mean(pr, 'seconds') / _mean(re, 'seconds'):.3f}); violations reactive "
            f"{sum(r['violations'] for r in re)}, exact forecast "
            f"{sum(r['violations'] for r in pr)}.",
            "",
        ]
    lines += error_lines(runs)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=2, help="operator seeds per population")
    parser.add_argument("--lean", action="store_true", help="0.5 s holds: a quick look")
    parser.add_argument(
        "--no-regression", action="store_true", help="section 1 only (the shared desk)"
    )
    parser.add_argument(
        "--no-bound", action="store_true", help="skip section 3 (the perfect forecast)"
    )
    args = parser.parse_args(argv)
    jobs: list[tuple] = [
        ("desk", p, i, seed, s, args.lean)
        for p in POPULATIONS
        for i in INTERACTIONS
        for seed in range(args.seeds)
        for s in SEPARATIONS
    ]
    if not args.no_bound:
        jobs += [
            ("bound", p, seed, s, args.lean)
            for p in POPULATIONS
            for seed in range(args.seeds)
            for s in SEPARATIONS
        ]
    if not args.no_regression:
        jobs += [("regression", c, s, args.lean) for c in REGRESSION for s in SEPARATIONS]
    runs, wall = run_pool(one_run, jobs, args.workers)
    publish(report(runs, args, wall), REPORT, args.lean)
    return 0


if __name__ == "__main__":
    sys.exit(main())
