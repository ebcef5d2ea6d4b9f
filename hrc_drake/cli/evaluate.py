"""`hrc-drake evaluate`: the command line of the Monte Carlo evaluation (`hrc_drake.evaluate`).

Every check that can be made before the runs is made first, in this order: the output path, the
flags, the spec, the operator model, at cell level the scenario (a wrong key or type is one line)
and the number of runs (with an estimate of the time they take); only then the cost table, which
the first evaluation of a spec computes (with a progress line) and later ones read from the
cache, and the runs. This module joins the task level and the cell (`hrc_drake.cell.run.evaluate`),
which do not import each other the other way.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

from hrc_drake.evaluate import evaluate
from hrc_drake.evaluation_report import plot_times
from hrc_drake.evaluation_runs import Setup
from hrc_drake.hri.populations import make_operator_model
from hrc_drake.paths import UsageError, check_output_path, image_kind
from hrc_drake.progress import ProgressLine, duration
from hrc_drake.tasks.costs import CostTable, CostTableError, load_cost_table
from hrc_drake.tasks.deciders import DECIDERS
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.interaction import (
    DEFAULT_DELAYS,
    INTERFACES,
    MODES,
    Interaction,
    InteractionCosts,
    InteractionError,
    make_interaction,
)

EXIT_INTERRUPTED = 130  # the shell's status for a command ended by SIGINT (128 + 2)
DEFAULT_RUNS = 1000
DEFAULT_CELL_RUNS = 20
# Cell runs are closed-loop simulations of about half a minute each: more than this in one
# evaluation is days of machine time (the estimate says how many); thousands belong at task level.
MAX_CELL_RUNS = 1000
# Real-time factors of a cell run (planning included) on this 2-core machine, loaded to quiet:
# benchmarks/reports/evaluate_cell.md measured 18-47 s of wall time per run of about 36 s
# simulated. The estimate gives the range.
CELL_REAL_TIME_FACTORS = (0.75, 2.0)
# Task-level runs keep every run's result until the report (its p95 and the --plot histogram need
# every time): about 1.5 KB per run against `random` (15 tasks a run; 0.5 KB against
# `mistake-prone`), so memory grows with --runs. The mean's standard error at 10^6 runs is a
# thousandth of the times' spread, far below the 1 % between deciders (docs/evaluation.md): more
# runs only cost memory and hours, so they are refused with this limit in the message.
MAX_TASK_RUNS = 1_000_000
TASK_RUN_BYTES = 1500
# Serial task-level runs per second on the flange case (2-core machine, `exact` 1,700 against
# `random`, 4,000 against `follows`; `mpc` 140 against `random`): the estimate gives the range.
TASK_RUNS_PER_SECOND = (140, 4000)
# Task-level evaluations whose slowest estimate is longer than this say so before they start.
ESTIMATE_ABOVE_SECONDS = 30.0
# Robot seconds of a task edge when no cost table is at hand yet: the mean of the flange case's
# table (38 edges, 5.5-7.1 s; `hrc-drake costs`).
TYPICAL_ROBOT_SECONDS = 6.4


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def local_workers(workers: int | None, runs: int) -> int | None:
    """`--workers` capped at the CPUs this process may use and at the runs, with a note on
    stderr when capped: more processes than CPUs share the CPUs and only add start-up time
    (each builds its own decider)."""
    if workers is None or workers <= 1:
        return workers
    cpus = usable_cpus()
    capped = min(workers, cpus, runs)
    if capped < workers:
        why = f"this machine has {cpus} CPU(s)" if capped == cpus else f"there are {runs} runs"
        print(f"note: --workers {workers}: {why}; using {capped}", file=sys.stderr)
    return capped


def parse_params(items: list[str] | None) -> dict[str, int | float | bool | str]:
    """``["p=0.3", "n=2", "order=S23"]`` -> ``{"p": 0.3, "n": 2, "order": "S23"}``: each value
    typed as a scenario's `operator.params` holds it (the report, its JSON and the replay
    commands show numbers as numbers); UsageError for an item that is not KEY=VALUE."""
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--param {item!r}: write KEY=VALUE, e.g. --param p=0.3")
        params[key.strip()] = param_value(key.strip(), value.strip())
    return params


def param_value(key: str, text: str) -> int | float | bool | str:
    """One `--param` value: a whole number, a number, `true`/`false`, else the text (a task
    token such as `S23`). UsageError for NaN or infinity, which no model parameter can use."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            number = kind(text)
        except ValueError:
            continue
        if not math.isfinite(number):
            raise UsageError(f"--param {key}={text}: give a finite number")
        return number
    return text


def interaction_from_flags(args) -> Interaction:
    """The `--interaction` mode and `--interface` (defaults: anticipate, pointer, with the
    interface's delay); UsageError naming the flag and the choices otherwise."""
    try:
        return make_interaction(
            getattr(args, "interaction", None), getattr(args, "interface", None)
        )
    except InteractionError as err:
        flag = "--interaction" if "mode" in str(err) else "--interface"
        raise UsageError(f"{flag}: {err}") from None


def add_interaction_flags(p, cell_note: str = "") -> None:
    """Register `--interaction` and `--interface` on the parser `p`; `cell_note` is added to the
    help of `--interaction` (what the cell does with it)."""
    delays = ", ".join(f"{k} {v.median:g} s" for k, v in DEFAULT_DELAYS.items())
    p.add_argument(
        "--interaction",
        default=None,
        metavar="MODE",
        help=f"{' or '.join(MODES)} (default anticipate): the robot starts on its prediction, or "
        f"waits for the operator's indication{cell_note}",
    )
    p.add_argument(
        "--interface",
        default=None,
        metavar="NAME",
        help=f"{', '.join(INTERFACES)} (default pointer): sets the indication delay (median "
        f"{delays}; our assumption, see docs/evaluation.md)",
    )


def add_separation_flag(p, note: str = "") -> None:
    """Register `--separation` on the parser `p`."""
    p.add_argument(
        "--separation",
        default=None,
        metavar="MODE",
        help="predictive (the robot times its moves around where it forecasts the operator, "
        "monitoring underneath) or reactive (speed and separation monitoring alone); default: "
        f"the scenario's `safety.separation`, predictive{note}",
    )


def separation_from_flags(args) -> str | None:
    """The `--separation` mode (None: the scenario's); UsageError naming the choices."""
    from hrc_drake.scenario.check import SEPARATION_MODES

    mode = getattr(args, "separation", None)
    if mode is not None and mode not in SEPARATION_MODES:
        raise UsageError(
            f"--separation: unknown mode {mode!r}; use {' or '.join(SEPARATION_MODES)}"
        )
    return mode


def _check_flags(args) -> Path | None:
    """The checks that need nothing loaded; the `--plot` path."""
    interaction_from_flags(args)
    separation_from_flags(args)
    plot = None
    if args.plot is not None:
        from hrc_drake.tasks.plots import FORMATS

        kind = image_kind(Path(args.plot).suffix)
        plot = check_output_path(args.plot, "--plot", FORMATS, kind=kind, force=args.force)
    if args.decider not in DECIDERS:
        raise UsageError(f"unknown decider {args.decider!r}; known deciders: {', '.join(DECIDERS)}")
    unused = ["--gamma"] if args.gamma is not None else []
    if args.mistake_prob != 0.05:  # the common option's default
        unused.append("--mistake-prob")
    if unused:
        raise UsageError(
            f"{', '.join(unused)}: not used by evaluate (each decider has its own model); set "
            "the operator population's parameters with --param, e.g. --param p=0.3"
        )
    cell_only = [
        f
        for f, v in (
            ("--lean", args.lean),
            ("--scenario", args.scenario),
            ("--separation", args.separation),
        )
        if v
    ]
    if args.scenario_text:
        cell_only.append("--scenario-text")
    if cell_only and not args.cell:
        raise UsageError(f"{', '.join(cell_only)}: only for runs through the cell; add --cell")
    if args.runs is not None and args.runs < 1:
        raise UsageError(f"--runs {args.runs}: give at least 1 run")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers {args.workers}: give at least 1 worker")
    if not args.cell and args.runs is not None:
        _check_task_runs(args.runs, args.workers if args.ray is None else None)
    if args.keep_model and (args.ray is not None or (args.workers or 1) > 1):
        raise UsageError(
            "--keep-model: one operator's assemblies follow each other, each learning from the "
            "last; they run in one process: drop --workers and --ray"
        )
    return plot


def _check_task_runs(runs: int, workers: int | None) -> None:
    """Task level: refuse more than MAX_TASK_RUNS runs (one line, with the estimate); say how
    long and how much memory a long evaluation takes before it starts."""
    workers = max(1, min(workers or 1, usable_cpus()))
    slow, fast = (runs / (rate * workers) for rate in TASK_RUNS_PER_SECOND)
    memory = runs * TASK_RUN_BYTES / 1e6
    size = f"{memory / 1000:.1f} GB" if memory >= 1000 else f"{max(memory, 1):.0f} MB"
    estimate = (
        f"about {duration(fast)} to {duration(slow)} of wall time on {workers} worker(s) and "
        f"up to {size} of memory for the report"
    )
    if runs > MAX_TASK_RUNS:
        raise UsageError(
            f"--runs {runs}: {estimate}; at most {MAX_TASK_RUNS:,} runs per evaluation (the "
            "figures settle long before: the mean's error at 10^6 runs is 0.1 % of the spread); "
            "give fewer, or repeat with other --seed values"
        )
    if slow > ESTIMATE_ABOVE_SECONDS:
        print(f"evaluate: {runs} runs, {estimate}", file=sys.stderr)


def _cell_options(args, space: StateSpace, operator):
    """The cell's options, checked now: the scenario loads (a wrong key or type is a one-line
    ScenarioError) and the operator model is one the cell can play."""
    from hrc_drake.cell.run.evaluate import DEFAULT_BASE_SCENARIO, CellOptions
    from hrc_drake.cell.scenario import LEAN

    separation = separation_from_flags(args)
    mode = None if separation is None else f"{{safety: {{separation: {separation}}}}}"
    overrides = [t for t in (LEAN if args.lean else None, *(args.scenario_text or []), mode) if t]
    # The cost table's file goes into the failing runs' replay commands (empty: the cache's).
    costs = "" if args.costs is None else str(Path(args.costs).resolve())
    cell = CellOptions(args.scenario or DEFAULT_BASE_SCENARIO, tuple(overrides), costs=costs)
    cell.check(operator, args.operator_model)
    scenario = cell.prepare(space)
    if scenario.policy:
        # The decider proposes every task; a policy file would be silently ignored.
        raise UsageError(
            f"the scenario's policy: {scenario.policy} is not used by evaluate (--decider "
            f"{args.decider} proposes every task); drop it from the scenario, or run the policy "
            "with `hrc-drake simulate`"
        )
    return cell, scenario


def cell_run_estimate(
    space: StateSpace, costs: CostTable | None, scenario, delay: float = 0.0
) -> float:
    """Simulated seconds of one cell run: the fewest tasks to finish, each the mean robot time
    of a task edge in `costs` (without: `TYPICAL_ROBOT_SECONDS`) plus the scenario's bolting
    hold and settling time, and the mean indication `delay` the robot waits for."""
    from hrc_drake.tasks.solve import tasks_to_finish

    tasks = max(1, int(tasks_to_finish(space)[0]))
    robot = [] if costs is None else [e.robot for e in costs.entries.values() if e.robot]
    mean_robot = sum(robot) / len(robot) if robot else TYPICAL_ROBOT_SECONDS
    return tasks * (mean_robot + scenario.motion.hold_time + scenario.run.settle_time + delay)


def cell_interaction(args, scenario) -> Interaction:
    """The interaction of a cell evaluation: the base scenario's `interaction` section, with
    `--interaction` and `--interface` over it (a delay the scenario gives stays)."""
    it = scenario.interaction
    delay = scenario.interaction_model().delay if it.delay is not None else None
    flags = interaction_from_flags(args)  # checked (one line) whatever the scenario says
    mode = it.mode if getattr(args, "interaction", None) is None else flags.mode
    interface = it.interface if getattr(args, "interface", None) is None else flags.interface
    return make_interaction(mode, interface, delay)


def _check_cell_runs(runs: int, workers: int | None, seconds: float) -> None:
    """Say at once how long the cell runs take; refuse more than MAX_CELL_RUNS."""
    per_worker = -(-runs // max(1, workers or 1))
    fast, slow = (per_worker * seconds / f for f in reversed(CELL_REAL_TIME_FACTORS))
    estimate = (
        f"about {seconds:.0f} s simulated per run, {duration(fast)} to {duration(slow)} of wall "
        f"time on {workers or 1} worker(s)"
    )
    if runs > MAX_CELL_RUNS:
        raise UsageError(
            f"--runs {runs} with --cell: {estimate}; at most {MAX_CELL_RUNS} cell runs per "
            "evaluation: evaluate thousands of runs at task level (drop --cell)"
        )
    print(f"evaluate --cell: {runs} run(s), {estimate}", file=sys.stderr)


def _cost_table(args, space: StateSpace, scenario=None) -> CostTable:
    """`--costs FILE`, or the cell's table: computed (with a progress line) the first time for
    a spec and layout, then read from the cache. With a cell's `scenario`, the edges the robot
    cannot plan are priced at its ``run.handover_time``, as its simulated operator takes them.
    CellModelError (the UR3 cannot reach the layout) is a one-line UsageError."""
    from hrc_drake.cell.run.costs import HANDOVER_TIME

    handover = HANDOVER_TIME if scenario is None else scenario.run.handover_time
    if args.costs is not None:
        return load_cost_table(args.costs, space).with_handover_time(handover)
    from hrc_drake.cell.run.costs import default_cost_table
    from hrc_drake.cell_models import CellModelError

    label = f"cost table of {space.spec.name} (planned once, then cached)"
    try:
        with ProgressLine(label, "plan") as bar:
            return default_cost_table(space, progress=bar.update).with_handover_time(handover)
    except CellModelError as err:
        raise UsageError(str(err)) from None


def cmd_evaluate(args) -> int:
    """`hrc-drake evaluate`: Monte Carlo runs of a decider against an operator model."""
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    plot = _check_flags(args)
    space = generate_states(load_spec(args.assembly))
    params = parse_params(args.param)
    operator = make_operator_model(args.operator_model, space, seed=0, **params)
    cell, scenario = (None, None) if not args.cell else _cell_options(args, space, operator)
    runs = args.runs if args.runs is not None else (DEFAULT_CELL_RUNS if cell else DEFAULT_RUNS)
    workers = args.workers if args.ray is not None else local_workers(args.workers, runs)
    interaction = interaction_from_flags(args)
    if cell is not None:
        interaction = cell_interaction(args, scenario)
    delay = interaction.delay.mean if cell is not None else 0.0
    if cell is not None and runs > MAX_CELL_RUNS:  # refused before the cost table is built
        _check_cell_runs(runs, workers, cell_run_estimate(space, None, scenario, delay))
    costs = _cost_table(args, space, scenario)
    if cell is not None:
        _check_cell_runs(runs, workers, cell_run_estimate(space, costs, scenario, delay))
    try:
        InteractionCosts(space, costs, interaction)  # the table has what the mode needs
    except CostTableError as err:
        raise UsageError(str(err)) from None
    setup = Setup(
        space, costs, args.decider, args.operator_model, params, args.seed,
        interaction=interaction, keep_model=args.keep_model, cell=cell,
    )  # fmt: skip
    report = _run_evaluation(args, setup, runs, workers)
    return _report(args, report, plot)


def _run_evaluation(args, setup: Setup, runs: int, workers: int | None) -> dict:
    """The runs, with a progress line; at cell level a CellModelError (the cell cannot be built
    for a run's scenario) is a one-line UsageError."""
    misfits: tuple[type[Exception], ...] = ()  # none at task level (which needs no Drake)
    if setup.cell is not None:
        from hrc_drake.cell_models import CellModelError

        misfits = (CellModelError,)
    level = "cell" if setup.cell else "evaluate"
    with ProgressLine(f"{level} {args.decider} vs {args.operator_model}", unit="run") as line:
        try:
            return evaluate(
                setup,
                runs,
                workers,
                progress=line.update,
                ray=args.ray is not None,
                ray_address=args.ray or None,
            )
        except misfits as err:
            raise UsageError(str(err)) from None


def _report(args, report: dict, plot: Path | None) -> int:
    """Plot the times (`--plot`), print the report (as JSON with `--json`) and return the exit
    status: EXIT_INTERRUPTED, with one line on stderr, when Ctrl-C cut the runs short; 1, with
    one line on stderr, when a cell run failed (as `simulate` exits 1 for a run that stopped:
    a script must not read a failing evaluation as a good one); else 0."""
    if plot is not None and report["completed"]:
        plot_times(report, plot)
    report.pop("times")
    if plot is not None and not report["completed"]:
        # The histogram is of completed runs' times: an empty one would look like a result.
        print(_nothing_to_plot(report, plot), file=sys.stderr)
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print_report(report)
    if report["interrupted"]:
        # After the report of the runs done: the one line that says why it ends here.
        done, asked = report["runs"], report["runs_requested"]
        print(f"hrc-drake evaluate: interrupted after {done} of {asked} runs", file=sys.stderr)
        return EXIT_INTERRUPTED
    failing = report.get("failures")
    if failing:
        print(
            f"hrc-drake evaluate: {len(failing)} of {report['runs']} cell runs failed "
            "(each listed under failures, with the command that replays it)",
            file=sys.stderr,
        )
        return 1
    return 0


# The unit of each figure of the text report (the JSON's keys carry none: docs/evaluation.md,
# "The report"); a key not listed (a name, a mode, a flag, a count of workers) is printed as it
# is.
REPORT_UNITS = {
    "runs": "runs",
    "completed": "runs",
    "completion_rate": "(fraction of the runs)",
    "capped": "runs (ended by the task cap)",
    "mean_time": "s per completed run",
    "p95_time": "s",
    "worst_time": "s",
    "mean_tasks": "tasks per run",
    "mean_undos": "undos per run",
    "mean_deviations": "deviations per run",
    "mean_idle": "s per task boundary",
    "p95_idle": "s",
    "plan_ready_rate": "(fraction of the task boundaries)",
    "commit_rate": "(fraction of the task boundaries)",
    "mean_retargets": "re-targets per run",
    "mean_swaps": "swaps per run",
    "mean_indication_delay": "s per run",
    "mean_indication_wait": "s per run",
    "collisions": "robot collisions",
    "handovers": "tasks done by the operator",
    "runs_with_handovers": "runs",
    "wall_mean_idle": "s of wall time per task boundary",
    "runs_requested": "runs",
    "wall_seconds": "s of wall time",
    "wall_runs_per_second": "runs per s of wall time",
}


def report_line(key: str, value) -> str:
    """One `key value unit` line of the text report: the parameters as `p=0.3`, the delay as
    its distribution, a figure with its unit (`REPORT_UNITS`), none for a figure no run gave."""
    if key == "params":
        text = " ".join(f"{k}={v}" for k, v in value.items()) or "none"
    elif key == "indication_delay" and isinstance(value, dict):
        text = ", ".join(
            f"{k} {v}{' s' if k in ('median', 'mean') else ''}" for k, v in value.items()
        )
    elif value is None:
        text = "n/a"
    elif key in REPORT_UNITS and not isinstance(value, bool):
        text = f"{value} {REPORT_UNITS[key]}"
    else:
        text = str(value)
    return f"{key:22} {text}"


def _nothing_to_plot(report: dict, plot: Path) -> str:
    """The one line that says `--plot` wrote nothing: why, and what to do."""
    kept = " (the file there is an earlier one, left as it was)" if plot.exists() else ""
    fix = (
        "see the failures and their replay commands; a larger run.max_sim_time or fewer "
        "mistakes let runs finish"
        if report.get("failures")
        else "run more runs"
    )
    return (
        f"hrc-drake evaluate: --plot {plot}: nothing to plot, not written{kept}: none of the "
        f"{report['runs']} run(s) completed (the histogram shows completed runs' times); {fix}"
    )


def print_report(report: dict) -> None:
    """The report as `key value unit` lines (`report_line`); the failing cell runs
    (`failures`) one by one, each with why it stopped and the command that replays it."""
    for key, value in report.items():
        if key != "failures":
            print(report_line(key, value))
    failing = report.get("failures")
    if failing is None:
        return
    print(f"{'failures':22} {len(failing)} runs")
    for f in failing:
        params = " ".join(f"{k}={v}" for k, v in f["params"].items())
        who = f"{f['operator_model']}{' ' + params if params else ''}, seed {f['seed']}"
        print(f"  run {f['run']} ({who}): {f['stop']}")
        print(f"    states: {' '.join(f['states'])}")
        print(f"    replay: {f['replay'] or 'not alone (the decider learned over earlier runs)'}")


def add_evaluate_parser(add) -> None:
    """Register `evaluate` with `add(name, func, help)` of `hrc_drake.cli.build_parser`."""
    p = add("evaluate", cmd_evaluate, "Monte Carlo: a decider against an operator population")
    p.add_argument("--decider", required=True, help=f"one of {', '.join(DECIDERS)}")
    p.add_argument(
        "--operator-model",
        required=True,
        help="follows, random, habitual, mistake-prone, change-of-mind, slow",
    )
    _add_run_flags(p)
    _add_cell_flags(p)
    p.add_argument("--plot", type=Path, default=None, help="histogram of assembly times")
    p.add_argument("--costs", type=Path, default=None, help="cost table (default: the cell's)")
    p.add_argument(
        "--param", action="append", default=None, help="operator model parameter KEY=VALUE"
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --plot file that is not an image of its kind",
    )
    add_interaction_flags(p, "; with --cell, over the scenario's `interaction.mode`")
    add_separation_flag(p, " (with --cell)")
    p.add_argument(
        "--keep-model",
        action="store_true",
        help="one operator, many assemblies: the decider keeps its operator model across the "
        "runs (serial)",
    )


def _add_run_flags(p) -> None:
    """Register how many runs `evaluate` plays and where: `--runs`, `--workers`, `--ray`."""
    p.add_argument(
        "--runs",
        type=int,
        default=None,
        help=f"runs (default {DEFAULT_RUNS}, at most {MAX_TASK_RUNS:,}; with --cell "
        f"{DEFAULT_CELL_RUNS}, at most {MAX_CELL_RUNS})",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="local processes (default 1, at most one per CPU); with --ray, Ray actors "
        "(default one per CPU of the cluster)",
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=None,
        metavar="ADDRESS",
        help="spread the runs on a Ray cluster at ADDRESS (no address: a local one); needs the "
        "extra hrc_drake[ray]",
    )


def _add_cell_flags(p) -> None:
    """Register the runs through the cell: `--cell`, and the scenario they play (`--scenario`,
    `--lean`, `--scenario-text`)."""
    p.add_argument(
        "--cell",
        action="store_true",
        help="run through the physical cell (closed-loop simulations; dozens, not thousands)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        help="with --cell: the base scenario (default row1-optimal; its operator is replaced)",
    )
    p.add_argument("--lean", action="store_true", help="with --cell: short holds (tests)")
    p.add_argument(
        "--scenario-text",
        action="append",
        default=None,
        help="with --cell: YAML overrides of the base scenario",
    )
