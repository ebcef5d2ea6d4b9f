"""Benchmark of the cell: build time and real-time factor of a settling run, settings side by side.

    python benchmarks/bench_cell.py [--duration 1.0] [--repeats 2]

Run on demand (not part of pytest). The settling run drops the three parts of state 11 (F3, S12,
F01) a few mm above their seats and simulates `duration` seconds in the station
(`make_cell_station`, the operator's body resting beside the table); the arm, when present, is
held by its PD actuators. Writes benchmarks/reports/cell.md (or `--out`).
"""

import argparse
import importlib.metadata
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform

from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.scenario import load_cell_scenario
from hrc_drake.cell.station import make_cell_station, simulate_station, station_scenario
from hrc_drake.scenario.schema import Scenario

REPORT = Path(__file__).resolve().parent / "reports" / "cell.md"
STATE_11 = {"oval_flange_1": "F3", "square_flange": "S12", "oval_flange_2": "F01"}


@dataclass(frozen=True)
class Setting:
    name: str
    include_robot: bool
    time_step: float
    approximation: str = "sap"
    meshcat: bool = False


SETTINGS = (
    Setting("lean: workpieces only, 10 ms", False, 1e-2),
    Setting("full: arm held, 10 ms (default)", True, 1e-2),
    Setting("full, 5 ms", True, 5e-3),
    Setting("full, 10 ms, lagged approximation", True, 1e-2, "lagged"),
    Setting("full, 2 ms", True, 2e-3),
    Setting("full, 10 ms, Meshcat recording", True, 1e-2, meshcat=True),
)


def _scenario(setting: Setting) -> Scenario:
    plant = (
        f"{{plant_config: {{time_step: {setting.time_step}, "
        f"discrete_contact_approximation: {setting.approximation}}}}}"
    )
    scenario = load_cell_scenario(None, plant)
    return station_scenario(scenario, robot=setting.include_robot)


_MESHCAT: list[Meshcat] = []  # one Meshcat server for every recording run


def run(setting: Setting, duration: float) -> dict:
    """Build once, then one settling run: build time, wall time, RTF and what the monitor read."""
    meshcat = None
    if setting.meshcat:
        if not _MESHCAT:
            _MESHCAT.append(Meshcat())
        meshcat = _MESHCAT[0]
    t0 = time.perf_counter()
    station = make_cell_station(_scenario(setting), meshcat)
    build = time.perf_counter() - t0
    context = station.create_default_context()
    plant, plant_context = station.plant, station.plant.GetMyContextFromRoot(context)
    for part, X in station.placement_poses(STATE_11).items():
        lift = 0.006 if part == "oval_flange_2" else 0.003
        plant.SetFreeBodyPose(
            plant_context, station.part_body(part), X @ RigidTransform([0.0005, -0.0005, lift])
        )
    recording = None
    if setting.meshcat:
        recording = Path(tempfile.mkdtemp()) / "settling.html"
    t0 = time.perf_counter()
    simulate_station(station, context, duration, recording=recording)
    wall = time.perf_counter() - t0
    speed = max(
        float(
            np.linalg.norm(plant.EvalBodySpatialVelocityInWorld(plant_context, b).translational())
        )
        for b in (station.part_body(p) for p in STATE_11)
    )
    tokens = station.configuration(context).tokens()
    return {
        "build": build,
        "wall": wall,
        "rtf": duration / wall,
        "speed": speed,
        "read": "ok" if tokens == frozenset(STATE_11.values()) else "+".join(sorted(tokens)),
    }


def main(argv: list[str] | None = None) -> int:
    """Run every setting `repeats` times; report the best real-time factor of each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPORT)
    args = parser.parse_args(argv)
    rows = []
    for setting in SETTINGS:
        runs = [run(setting, args.duration) for _ in range(args.repeats)]
        best = max(runs, key=lambda r: r["rtf"])
        best["build"] = min(r["build"] for r in runs)
        rows.append((setting, best))
        print(
            f"{setting.name:38s} build {best['build']:.2f} s  RTF {best['rtf']:.2f}  "
            f"max part speed {best['speed'] * 1000:.2f} mm/s  read {best['read']}"
        )
    lines = [
        "# Cell benchmark",
        "",
        f"`python benchmarks/bench_cell.py --duration {args.duration} --repeats {args.repeats}`"
        f" — drake {importlib.metadata.version('drake')}, "
        f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}.",
        "",
        f"Settling run: the parts of state 11 (F3, S12, F01) let go 3–6 mm above their seats, "
        f"{args.duration} s simulated; hydroelastic_with_fallback, polygon surfaces. RTF = "
        f"simulated / wall time, best of {args.repeats}; build = `make_cell_station` wall time, "
        f"best of {args.repeats}; speed = fastest part at the end; read = the configuration "
        "sensor's tokens equal {F3, S12, F01}. The station is the one a run builds (the "
        "operator's body beside the table, resting; the arm, when present, held still).",
        "",
        "Why `sap` is the default although `lagged` runs faster here: in a harder drop (1 mm off, "
        "1° tilt, 3 mm above slot 1) the 67 g oval flange never came to rest under `lagged` or "
        "`similar` at 5 ms (0.4 N of its 0.66 N weight carried, ~9 mm/s residual velocity after "
        "2 s, pose frozen in the seat), and rests exactly under `sap`; the bolts' weld "
        "constraints need a SAP-family approximation. The contact material is the scenario's "
        "default (calibrated in benchmarks/reports/contact.md).",
        "",
        "| setting | time step | approximation | build [s] | RTF | part speed at end [mm/s] "
        "| read |",
        "|---|---|---|---|---|---|---|",
    ]
    for setting, r in rows:
        lines.append(
            f"| {setting.name} | {setting.time_step:g} | {setting.approximation} | "
            f"{r['build']:.2f} | {r['rtf']:.2f} | {r['speed'] * 1000:.2f} | {r['read']} |"
        )
    atomic_write_text(args.out, "\n".join(lines) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
