"""Real-time factor of a full closed-loop run with friction grasps, beside the same run with grasp
welds, and where the time goes.

    python benchmarks/bench_friction_rtf.py --weld-tree DIR [--repeats 3] [--scenario NAME]

`DIR` is a source tree whose cell holds parts with grasp welds (before issue 17), e.g.
`mkdir DIR && git archive 9ce761f | tar -x -C DIR`. Each configuration runs in a process of its
own with that tree first on `sys.path`: `run_scenario(NAME)` once (plans are made and cached in
the planning worker), then `--repeats` timed runs (wall and CPU time of the process, which
excludes the planning worker), the station alone holding still (the ratio base: the closed
loop's RTF over it), and one run timed per phase of the tasks (CPU). Full settings (5 s bolting
holds, the collaborative speed), the operator's body and the separation monitor on. The
operator's indication delay is set to 0 where the tree has one, so that every configuration
simulates the same timeline as the weld tree's; one configuration keeps the default delays.
Writes benchmarks/reports/friction_rtf.md.
"""

from __future__ import annotations

import argparse
import collections
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from timing import best_cpu_rtf

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REPORT = HERE / "reports" / "friction_rtf.md"
NO_DELAY = "{interaction: {delay: {distribution: fixed, median: 0.0}}}"
BEFORE = (
    "{plant_config: {time_step: 0.005}, scene_graph_config: {default_proximity_properties: "
    "{hydroelastic_modulus: 2.0e7, relaxation_time: 0.1, margin: 0.0}}}"
)


@dataclass(frozen=True)
class Configuration:
    """A run to time: a source tree and scenario texts on top of the scenario."""

    name: str
    tree: Path
    texts: tuple[str, ...] = ()


def _worker(tree: str, scenario: str, texts: list[str], repeats: int) -> dict:
    """In a fresh process: time the runs (see the module docstring); a JSON-able summary."""
    sys.path.insert(0, tree)
    from pydrake.systems.analysis import Simulator

    from hrc_drake.cell.run.run import build_closed_loop, run_scenario
    from hrc_drake.cell.scenario import load_cell_scenario, plant_step
    from hrc_drake.cell.station.build import make_cell_station
    from hrc_drake.scenario.schema import Scenario

    if not hasattr(Scenario(), "interaction"):
        texts = [t for t in texts if t != NO_DELAY]
    loaded = load_cell_scenario(scenario, texts or None)
    first = run_scenario(loaded)
    runs = []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        result = run_scenario(loaded)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        runs.append(
            {
                "sim": result.sim_time,
                "wall": wall,
                "cpu": cpu,
                "done": result.done,
                "names": result.names,
                "collisions": len(result.collisions),
            }
        )
    station = make_cell_station(loaded)
    context = station.create_default_context()
    simulator = Simulator(station.diagram, context)
    simulator.AdvanceTo(0.2)
    wall, cpu = time.perf_counter(), time.process_time()
    simulator.AdvanceTo(5.2)
    at_rest = {"wall": 5.0 / (time.perf_counter() - wall), "cpu": 5.0 / (time.process_time() - cpu)}
    return {
        "time_step": plant_step(loaded),
        "first": {"names": first.names, "done": first.done, "error": first.error},
        "runs": runs,
        "at_rest": at_rest,
        "phases": _phases(build_closed_loop(loaded)),
    }


def _phases(loop) -> dict[str, list[float]]:
    """Per phase of the tasks: [simulated s, CPU s] of one run, in 0.1 s pieces."""
    acc: dict[str, list[float]] = collections.defaultdict(lambda: [0.0, 0.0])
    t = 0.0
    while True:
        status = loop.status
        phase = status.mode.value
        if phase == "execute" and status.plan is not None:
            tau = status.plan_time(loop.simulator.get_context().get_time())
            phase = next(
                (s.stage.value for s in status.plan.segments if s.start <= tau < s.end), "end"
            )
            if status.holding_for_bolts(tau):
                phase = "hold for bolts"
        cpu = time.process_time()
        mode = loop.advance_to(t + 0.1)
        acc[phase][0] += 0.1
        acc[phase][1] += time.process_time() - cpu
        t += 0.1
        if mode.value in ("done", "failed") or t > 300:
            return dict(acc)


def hold_levers(scenario_name: str, repeats: int) -> dict[str, float]:
    """The station alone in row 1's costliest phase (the square flange held in S23 for its
    bolts, F1 bolted; lean settings to get there): CPU RTF as the station is (a bolted part
    locked, its contact with its support filtered out), with those contacts kept, and without
    the operator's body."""
    import dataclasses

    from pydrake.systems.analysis import Simulator

    from hrc_drake.cell.run.run import build_closed_loop
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario
    from hrc_drake.cell.station.build import make_cell_station
    from hrc_drake.cell.station.welds import Weld

    scenario = load_cell_scenario(scenario_name, [LEAN, NO_DELAY])
    loop = build_closed_loop(scenario)
    t = 0.0
    while not (
        loop.status.plan is not None
        and loop.status.plan.instance == "square_flange"
        and loop.status.holding_for_bolts(loop.status.plan_time(t))
    ):
        t += 0.05
        loop.advance_to(t)
    plant = loop.station.plant
    x = plant.GetPositions(plant.GetMyContextFromRoot(loop.root_context))
    opening = loop.status.command(t).opening
    bolts = {Weld("oval_flange_1", "F1"), Weld("square_flange", "S23")}

    def rtf(station, filtered: bool) -> float:
        context = station.create_default_context()
        plant_context = station.plant.GetMyMutableContextFromRoot(context)
        station.plant.SetPositions(plant_context, x)
        station.hold_robot(context, opening=opening)
        filters = station.scene_graph.collision_filter_manager(
            station.scene_graph.GetMyMutableContextFromRoot(context)
        )
        if filtered:
            station.bolts.apply(plant_context, bolts, filters)
        else:
            # The bolted parts' floating joints locked, their contacts with the plate kept.
            for weld in bolts:
                station.bolts.joints[weld.part].Lock(plant_context)
        return best_cpu_rtf(Simulator(station.diagram, context), 1.0, repeats)

    full = load_cell_scenario(scenario_name, [NO_DELAY])
    station = make_cell_station(full)
    nobody = make_cell_station(
        dataclasses.replace(full, body=dataclasses.replace(full.body, enabled=False))
    )
    return {
        "as it is (bolted parts' contacts with their supports filtered out)": rtf(station, True),
        "bolted parts' contacts kept": rtf(station, False),
        "no operator body": rtf(nobody, True),
    }


def _measure(configuration: Configuration, scenario: str, repeats: int) -> dict:
    command = [
        sys.executable,
        __file__,
        "--worker",
        str(configuration.tree),
        scenario,
        json.dumps(list(configuration.texts)),
        str(repeats),
    ]
    env = dict(os.environ, PYTHONPATH=str(configuration.tree))
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{configuration.name}: {done.stderr.strip().splitlines()[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _row(configuration: Configuration, r: dict) -> str:
    runs = r["runs"]
    walls = [x["sim"] / x["wall"] for x in runs]
    cpus = [x["sim"] / x["cpu"] for x in runs]
    ok = all(x["done"] and x["collisions"] == 0 for x in runs) and r["first"]["done"]
    base = r["at_rest"]["cpu"]
    return (
        f"| {configuration.name} | {r['time_step'] * 1000:g} | {runs[0]['sim']:.1f} | "
        f"{min(walls):.2f}–{max(walls):.2f} | {min(cpus):.2f}–{max(cpus):.2f} | "
        f"{r['at_rest']['cpu']:.2f} | {max(cpus) / base:.2f} | "
        f"{' '.join(runs[0]['names'])} | {'yes' if ok else 'no'} |"
    )


def _phase_table(results: list[tuple[Configuration, dict]]) -> list[str]:
    order = ["hold for bolts", "carry", "place", "grasp", "release", "approach", "retreat"]
    lines = [
        "| configuration | " + " | ".join(order) + " | rest of the run |",
        "|---" * (len(order) + 2) + "|",
    ]
    for configuration, r in results:
        phases = r["phases"]
        total = sum(cpu for _sim, cpu in phases.values())
        cells = []
        for name in order:
            sim, cpu = phases.get(name, (0.0, 0.0))
            cells.append(f"{sim / cpu:.2f} ({cpu / total:.0%})" if cpu else "—")
        rest = [v for k, v in phases.items() if k not in order]
        sim, cpu = sum(v[0] for v in rest), sum(v[1] for v in rest)
        cells.append(f"{sim / cpu:.2f} ({cpu / total:.0%})" if cpu else "—")
        lines.append(f"| {configuration.name} | " + " | ".join(cells) + " |")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Time every configuration and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--weld-tree", type=Path, required=True)
    parser.add_argument("--weld-commit", default="9ce761f", help="for the report only")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenario", default="row1-optimal")
    parser.add_argument("--out", type=Path, default=REPORT)
    args = parser.parse_args(argv)
    configurations = [
        Configuration("friction grasps (defaults)", ROOT, (NO_DELAY,)),
        Configuration(
            "friction grasps, 5 ms step", ROOT, (NO_DELAY, "{plant_config: {time_step: 0.005}}")
        ),
        Configuration("friction grasps, contact settings before", ROOT, (NO_DELAY, BEFORE)),
        Configuration(f"grasp welds ({args.weld_commit})", args.weld_tree.resolve()),
        Configuration("friction grasps (defaults, indication delays on)", ROOT),
    ]
    results = []
    for configuration in configurations:
        result = _measure(configuration, args.scenario, args.repeats)
        results.append((configuration, result))
        print(_row(configuration, result), flush=True)
    lines = [
        "# Friction grasps: real-time factor beside grasp welds",
        "",
        f"`python benchmarks/bench_friction_rtf.py --weld-tree DIR --repeats {args.repeats} "
        f"--scenario {args.scenario}` (DIR: `git archive {args.weld_commit}`) — drake "
        f"{importlib.metadata.version('drake')}, {platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}. The figures are ranges over the repeats, and the "
        "CPU time of the controller's process (which excludes the planning worker and waiting "
        "for a core) is given beside the wall time: where the two agree, nothing else took the "
        "cores.",
        "",
        f"Each configuration: `{args.scenario}`, full settings (5 s bolting holds, TCP <= "
        "0.25 m/s), the operator's body and the separation monitor on, every plan cached (a "
        "first run made them). *RTF* = simulated / wall (or CPU) time; *at rest*: the station "
        "alone holding still (CPU), the ratio base; *ratio*: the best closed-loop CPU RTF over "
        "it. The indication delay is 0 but in the last row (the weld tree has none).",
        "",
        "| configuration | step [ms] | simulated [s] | RTF wall | RTF CPU | at rest (CPU) | ratio "
        "| states | terminal, 0 collisions |",
        "|---|---|---|---|---|---|---|---|---|",
        *(_row(c, r) for c, r in results),
        "",
        "## Where the time goes",
        "",
        "One run per configuration timed by phase of the tasks (CPU): the phase's RTF and its "
        "share of the run's CPU time. *hold for bolts*: the robot holds the placed part while "
        "the operator bolts it; *rest of the run*: deciding, waiting for the indication, "
        "settling.",
        "",
        *_phase_table(results),
        "",
    ]
    levers = hold_levers(args.scenario, args.repeats)
    lines += [
        "## Levers in the costliest phase",
        "",
        "The station alone (no controller) in the phase that takes most of a run: the square "
        "flange held in S23 for its bolts, F1 bolted (reached by a lean run of "
        f"`{args.scenario}`); CPU RTF, best of {args.repeats} one-second pieces.",
        "",
        "| station | RTF (CPU) |",
        "|---|---|",
        *(f"| {name} | {value:.2f} |" for name, value in levers.items()),
        "",
    ]
    from hrc_drake.atomic import atomic_write_text

    atomic_write_text(args.out, "\n".join(lines))
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        tree, scenario, texts, repeats = sys.argv[2:6]
        print(json.dumps(_worker(tree, scenario, json.loads(texts), int(repeats))))
        raise SystemExit(0)
    raise SystemExit(main())
