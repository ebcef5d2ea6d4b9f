"""Contact settings of the cell: settling, friction grasps and real-time factor, side by side.

    python benchmarks/bench_contact.py [--repeats 2] [--out PATH]

Run on demand (not part of pytest); the machine is shared, so real-time factors are the best of
`--repeats` and measured in CPU time of this process. Five experiments:

1. Settling, per contact setting: parts let go near their seats as the configuration tests do
   (1 mm off, 1° tilt, 3 mm above a plate seat, 6 mm above a host's row) in three
   configurations (F1; F3 S12 F01; F1 S23 F03), workpieces only: real-time factor, the time
   until every part is slower than 1 mm/s, whether the configuration sensor reads the
   configuration, and the largest horizontal distance of a part to its nominal seat at the end.
   Beside it the station at rest (arm, gripper, body, parts in the tray): the ratio base of the
   closed-loop benchmarks.
2. Friction grasps, default settings: the square flange (0.57 kg, the heaviest part of the
   flange case) held in the air at a grip force, the arm then accelerating the tcp at a steady
   rate for 50 ms and braking it as hard: the largest rate at which the part does not slip
   (moves less than 1 mm relative to the tcp), up, along the pads and across them.
3. What the carry asks: the largest tcp acceleration along row 1's plans (the
   collaborative-speed plans every Table 2 row uses), from the plans' trajectories.
4. A part pressed onto a pocket's rim, per hydroelastic modulus: the 4-slot cell's closed loop
   with the `no-seat` fault on its square flange (the part slid 8.3, 10.9 and 11.2 mm in the
   fingers, so the robot lowers it onto the rim while it still holds it): whether the run
   completes, its collisions, the largest finger contact force while the part is held, and
   how the run ended.
5. A part dropped across a pocket, per hydroelastic modulus: the oval flange let go 6 mm
   above a plate pocket, turned 0.6–1.57 rad from it (its boss longer than the pocket is wide),
   falling at 0.5–1.2 m/s (a lost grip), workpieces only: whether it rests on the rims or
   wedged in the pocket, held by contact forces far beyond its weight.

Writes benchmarks/reports/contact.md.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.metadata
import math
import os
import platform
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialVelocity
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from timing import best_cpu_rtf

import hrc_drake.cell_models as cell_models
from hrc_drake.atomic import atomic_write_text
from hrc_drake.cell.run.run import shared_planner
from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
from hrc_drake.cell.station import make_cell_station, station_scenario
from hrc_drake.motion.plan import Stage
from hrc_drake.motion.poses import default_layout
from hrc_drake.robot_models import set_rg2_opening
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.spec import load_spec

REPORT = Path(__file__).resolve().parent / "reports" / "contact.md"
DROPS = (
    (frozenset({"F1"}), 1),
    (frozenset({"F3", "S12", "F01"}), 11),
    (frozenset({"F1", "S23", "F03"}), 7),
)
REST_SPEED = 0.001  # m/s
SLIP = 0.001  # m
RATES = (2.0, 5.0, 10.0, 20.0, 30.0, 40.0, 60.0)  # m/s², tried in turn


@dataclass(frozen=True)
class Setting:
    """One contact setting: scenario text on top of the defaults; `rigid`: the plate and the
    tray rigid hydroelastic (an experiment: the models say compliant)."""

    name: str
    text: str = "{}"
    rigid: bool = False


SETTINGS = (
    Setting(
        "before: 5 ms, E 2e7 Pa, τ 0.1 s, no margin",
        "{plant_config: {time_step: 0.005}, scene_graph_config: {default_proximity_properties: "
        "{hydroelastic_modulus: 2.0e7, relaxation_time: 0.1, margin: 0.0}}}",
    ),
    Setting("5 ms, E 5e6 Pa, τ 1 ms, margin 0.1 mm", "{plant_config: {time_step: 0.005}}"),
    Setting("default: 10 ms, E 5e6 Pa, τ 1 ms, margin 0.1 mm"),
    Setting(
        "10 ms, E 1e7 Pa",
        "{scene_graph_config: {default_proximity_properties: {hydroelastic_modulus: 1.0e7}}}",
    ),
    Setting(
        "10 ms, τ 10 ms",
        "{scene_graph_config: {default_proximity_properties: {relaxation_time: 0.01}}}",
    ),
    Setting(
        "10 ms, τ 0.1 s",
        "{scene_graph_config: {default_proximity_properties: {relaxation_time: 0.1}}}",
    ),
    Setting(
        "10 ms, no margin", "{scene_graph_config: {default_proximity_properties: {margin: 0.0}}}"
    ),
    Setting(
        "10 ms, E 1e6 Pa",
        "{scene_graph_config: {default_proximity_properties: {hydroelastic_modulus: 1.0e6}}}",
    ),
    Setting("10 ms, rigid plate and tray", rigid=True),
    Setting("5 ms, rigid plate and tray", "{plant_config: {time_step: 0.005}}", rigid=True),
)


def _rigid(sdf: str) -> str:
    return sdf.replace(
        "</geometry>\n      </collision>",
        "</geometry>\n        <drake:proximity_properties>\n          <drake:rigid_hydroelastic/>"
        "\n        </drake:proximity_properties>\n      </collision>",
    )


@contextlib.contextmanager
def _models(rigid: bool) -> Iterator[None]:
    """The cell's generated plate and tray, made rigid hydroelastic if asked."""
    if not rigid:
        yield
        return
    plate, tray = cell_models.CellDesign.plate_sdf, cell_models.CellDesign.tray_sdf
    cell_models.CellDesign.plate_sdf = lambda self: _rigid(plate(self))
    cell_models.CellDesign.tray_sdf = lambda self: _rigid(tray(self))
    try:
        yield
    finally:
        cell_models.CellDesign.plate_sdf, cell_models.CellDesign.tray_sdf = plate, tray


def _drop(station, configuration: frozenset[str], seed: int) -> dict:
    """One settling run (see the module docstring)."""
    plant = station.plant
    context = station.create_default_context()
    plant_context = plant.GetMyContextFromRoot(context)
    placements = default_layout(station.frames, configuration)
    seated = station.placement_poses(placements)
    rng = np.random.default_rng(seed)
    for part, X in seated.items():
        dx, dy = rng.uniform(-0.0008, 0.0008, size=2)
        roll, pitch, yaw = rng.uniform(-math.radians(1), math.radians(1), size=3)
        lift = 0.006 if station.design.spec.placement(placements[part]).host else 0.003
        X_lift = RigidTransform(RollPitchYaw(roll, pitch, yaw), [dx, dy, lift])
        plant.SetFreeBodyPose(plant_context, station.part_body(part), X @ X_lift)
    simulator = Simulator(station.diagram, context)
    rest, step = None, 0.01
    cpu = time.process_time()
    while context.get_time() < 1.0 - 1e-9:
        simulator.AdvanceTo(context.get_time() + step)
        speed = max(
            np.linalg.norm(
                plant.EvalBodySpatialVelocityInWorld(
                    plant_context, station.part_body(p)
                ).translational()
            )
            for p in seated
        )
        rest = None if speed >= REST_SPEED else (rest or context.get_time())
    cpu = time.process_time() - cpu
    off = max(
        np.linalg.norm(
            seated[p]
            .InvertAndCompose(plant.EvalBodyPoseInWorld(plant_context, station.part_body(p)))
            .translation()[:2]
        )
        for p in seated
    )
    read = station.configuration(context).tokens() == configuration
    return {"rtf": 1.0 / cpu, "rest": rest, "read": read, "off": off}


def _at_rest_rtf(scenario: Scenario, repeats: int) -> float:
    """The whole station (arm, gripper, body, parts in the tray) holding still: its RTF."""
    station = make_cell_station(scenario)
    context = station.create_default_context()
    return best_cpu_rtf(Simulator(station.diagram, context), 2.0, repeats)


def settling(setting: Setting, repeats: int) -> dict:
    """Experiment 1 for one setting: the three drops (best RTF of `repeats`) and the station at
    rest."""
    scenario = load_cell_scenario(None, setting.text)
    with _models(setting.rigid):
        workpieces = make_cell_station(station_scenario(scenario, robot=False))
        runs = [[_drop(workpieces, c, seed) for c, seed in DROPS] for _ in range(repeats)]
        at_rest = _at_rest_rtf(scenario, repeats)
    drops = runs[0]
    rests = [d["rest"] for d in drops]
    return {
        "rtf": max(np.mean([d["rtf"] for d in run]) for run in runs),
        "rest": None if None in rests else max(rests),
        "read": sum(d["read"] for d in drops),
        "off": max(d["off"] for d in drops),
        "at_rest": at_rest,
    }


# A first task of the flange case that takes each part from the tray.
_FIRST_TASKS = {"F1": "oval_flange_1", "S23": "square_flange"}


@dataclass
class _Grip:
    """A station holding `part` in the air, ready to be accelerated."""

    station: object
    part: str
    q0: np.ndarray
    X_W_part: RigidTransform
    width: float

    @staticmethod
    def make(scenario: Scenario, part: str) -> _Grip:
        scenario = dataclasses.replace(
            scenario, body=dataclasses.replace(scenario.body, enabled=False)
        )
        station = make_cell_station(scenario)
        # Where the carry starts: the arm's posture at the end of the lift of a plan that takes
        # the part from the tray, and the part where the tcp then holds it.
        design = cell_design(scenario, load_spec(scenario.assembly_path))
        planner = shared_planner(motion_options(scenario), design)
        task = next(t for t, p in _FIRST_TASKS.items() if p == part)
        plan = planner.plan_task(frozenset(), task)
        lift = next(m for m in plan.motions if m.name == "lift")
        q0 = plan.positions(lift.start + lift.duration)
        plant = station.plant
        plant_context = plant.CreateDefaultContext()
        plant.SetPositions(plant_context, station.instances[UR3], q0)
        X_W_tcp = plant.GetFrameByName("tcp").CalcPoseInWorld(plant_context)
        X_W_part = X_W_tcp @ station.frames.grasps[part].inverse()
        return _Grip(station, part, q0, X_W_part, float(station.frames.widths[part]))

    def slip(self, force: float, direction: np.ndarray, rate: float) -> tuple[float, float]:
        """(slip of the part relative to the tcp [m], the tcp's largest measured acceleration
        [m/s²]) when the tcp accelerates at `rate` along `direction` for 50 ms, then brakes."""
        station, plant = self.station, self.station.plant
        context = station.create_default_context()
        plant_context = plant.GetMyMutableContextFromRoot(context)
        ur3, rg2 = station.instances[UR3], station.instances[GRIPPER]
        plant.SetPositions(plant_context, ur3, self.q0)
        set_rg2_opening(plant, plant_context, self.width, rg2)
        plant.SetFreeBodyPose(plant_context, station.part_body(self.part), self.X_W_part)
        squeeze = motion_options(station.scenario).grip_squeeze
        station.hold_robot(context, opening=self.width - squeeze, force=force)
        simulator = Simulator(station.diagram, context)
        simulator.AdvanceTo(0.3)
        tcp = plant.GetFrameByName("tcp", rg2)

        def relative() -> RigidTransform:
            X_W_tcp = tcp.CalcPoseInWorld(plant_context)
            X_W_part = plant.EvalBodyPoseInWorld(plant_context, station.part_body(self.part))
            return X_W_tcp.InvertAndCompose(X_W_part)

        start = relative()
        J = plant.CalcJacobianSpatialVelocity(
            plant_context,
            JacobianWrtVariable.kV,
            tcp,
            np.zeros(3),
            plant.world_frame(),
            plant.world_frame(),
        )
        columns = [plant.GetJointByName(n).velocity_start() for n in UR3_JOINTS]
        qdd = np.linalg.solve(J[:, columns], np.r_[np.zeros(3), rate * direction])
        h, T = plant.time_step(), 0.05
        t0, v_prev, peak = context.get_time(), None, 0.0
        for k in range(1, round(4 * T / h) + 1):
            t = k * h
            # +rate for T, -rate for T, then still.
            if t <= T:
                q, v = self.q0 + 0.5 * qdd * t**2, qdd * t
            elif t <= 2 * T:
                s = t - T
                q = self.q0 + 0.5 * qdd * T**2 + qdd * T * s - 0.5 * qdd * s**2
                v = qdd * (T - s)
            else:
                q, v = self.q0 + qdd * T**2, np.zeros(6)
            station.diagram.GetInputPort("ur3.position").FixValue(
                station.diagram.GetMyMutableContextFromRoot(context), q
            )
            station.diagram.GetInputPort("ur3.velocity").FixValue(
                station.diagram.GetMyMutableContextFromRoot(context), v
            )
            simulator.AdvanceTo(t0 + t)
            v_tcp = tcp.CalcSpatialVelocityInWorld(plant_context).translational()
            if v_prev is not None:
                peak = max(peak, float(np.linalg.norm(v_tcp - v_prev) / h))
            v_prev = v_tcp
        moved = start.InvertAndCompose(relative())
        return float(np.linalg.norm(moved.translation())), peak


def grip_limits(grip: _Grip, force: float) -> dict[str, tuple[float | None, float]]:
    """Experiment 2: per direction, (the largest rate without slip, None if even the smallest
    slips; the tcp's measured peak acceleration at that rate)."""
    X_W_grasp = grip.X_W_part @ grip.station.frames.grasps[grip.part]
    directions = {
        "up": np.array([0.0, 0.0, 1.0]),
        # The tcp's x runs along the part (the pads' plane), its y across the pads.
        "along the pads": X_W_grasp.rotation().col(0),
        "across the pads": X_W_grasp.rotation().col(1),
    }
    limits = {}
    for name, direction in directions.items():
        best, peak = None, 0.0
        for rate in RATES:
            moved, measured = grip.slip(force, direction, rate)
            if moved >= SLIP:
                break
            best, peak = rate, measured
        limits[name] = (best, peak)
    return limits


def carry_accelerations() -> dict[str, float]:
    """Experiment 3: the largest tcp acceleration [m/s²] (and the largest upward one) while the
    part is held, along row 1's three plans."""
    scenario = load_cell_scenario("row1-optimal")
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    planner = shared_planner(motion_options(scenario), design)
    station = make_cell_station(scenario)
    plant = station.plant
    plant_context = plant.CreateDefaultContext()
    tcp = plant.GetFrameByName("tcp", station.instances[GRIPPER])
    largest = upward = 0.0
    done: list[str] = []
    for task in ("F1", "S23", "F03"):
        plan = planner.plan_task(frozenset(done), task)
        done.append(task)
        start, end = plan.segment(Stage.GRASP).end, plan.t_release
        times = np.arange(start, end, 0.005)
        points = []
        for t in times:
            plant.SetPositions(plant_context, station.instances[UR3], plan.positions(t))
            points.append(tcp.CalcPoseInWorld(plant_context).translation())
        points = np.array(points)
        acc = np.diff(points, n=2, axis=0) / 0.005**2
        largest = max(largest, float(np.linalg.norm(acc, axis=1).max()))
        upward = max(upward, float(acc[:, 2].max()))
    return {"largest": largest, "upward": upward}


def main(argv: list[str] | None = None) -> int:
    """Run the three experiments and write the report."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPORT)
    args = parser.parse_args(argv)
    rows = []
    for setting in SETTINGS:
        result = settling(setting, args.repeats)
        rows.append((setting, result))
        print(setting.name, result, flush=True)
    grip = _Grip.make(Scenario(), "square_flange")
    default_force = Scenario().station.rg2.grip_force
    grips = {force: grip_limits(grip, force) for force in (default_force, 10.0, 5.0, 3.0)}
    for force, limits in grips.items():
        print(f"grip {force} N", limits, flush=True)
    carry = carry_accelerations()
    print("carry", carry, flush=True)
    pinch = {modulus: rim_pinch(modulus) for modulus in PINCH_MODULI}
    print("pinch", pinch, flush=True)
    drops = {modulus: drops_across_a_pocket(modulus) for modulus in PINCH_MODULI}
    print("drops", drops, flush=True)
    text = _report(args, rows, grips, carry, grip) + _pinch_report(pinch) + _drops_report(drops)
    atomic_write_text(args.out, text)
    return 0


PINCH_MODULI = (1.0e7, 5.0e6)  # Pa: Drake's default, ours
PINCH_OFFSETS = (0.0083, 0.0109, 0.0112)  # m, seeds 1, 4 and 0 of bench_faults on the 4-slot cell
PINCH_END = 120.0  # s, simulated: past the end of every run


def rim_pinch(modulus: float) -> list[dict]:
    """The 4-slot closed loop, its square flange (task 2) slid `PINCH_OFFSETS` in the fingers,
    at hydroelastic `modulus`: per offset, whether the run completed, its collisions, the
    largest contact force on a finger, and how it ended."""
    from hrc_drake.cell.controller.supervisor import Mode
    from hrc_drake.cell.run.run import build_closed_loop
    from hrc_drake.cell.station.contacts import geometry_owners

    runs = []
    for offset in PINCH_OFFSETS:
        texts = [
            "{assembly: four-slot, name: four-slot}",
            f"{{faults: [!NoSeat {{task: 2, offset: {offset}}}]}}",
            _modulus_text(modulus),
        ]
        loop = build_closed_loop(load_cell_scenario(None, texts))
        owners = geometry_owners(loop.station.plant)
        largest, t = 0.0, 0.0
        while loop.advance_to(t) not in (Mode.DONE, Mode.FAILED) and t < PINCH_END:
            largest = max(largest, _finger_force(loop, owners))
            t += loop.station.plant.time_step()
        result = loop.result()
        runs.append(
            {
                "offset": offset,
                "done": result.done,
                "collisions": len(result.collisions),
                "finger_force": largest,
                "end": result.error or "done",
            }
        )
    return runs


def _finger_force(loop, owners) -> float:
    """The largest contact force on a finger of the gripper now [N] (`owners`: the plant's
    `geometry_owners`)."""
    plant = loop.station.plant
    context = plant.GetMyContextFromRoot(loop.root_context)
    results = plant.get_contact_results_output_port().Eval(context)
    largest = 0.0
    for i in range(results.num_hydroelastic_contacts()):
        info = results.hydroelastic_contact_info(i)
        surface = info.contact_surface()
        bodies = [owners[g].body for g in (surface.id_M(), surface.id_N()) if g in owners]
        if any(body.endswith("finger") for body in bodies):
            largest = max(largest, float(np.linalg.norm(info.F_Ac_W().translational())))
    return largest


def _pinch_report(pinch: dict[float, list[dict]]) -> str:
    lines = [
        "## 4. A part pressed onto a pocket's rim",
        "",
        "The 4-slot cell with the `no-seat` fault on its square flange (task 2): the part slid "
        "in the fingers, so the robot lowers it onto the pocket's rim while it still holds it. "
        "Default settings but the hydroelastic modulus. *finger force*: the largest contact "
        "force on a finger in the run.",
        "",
        "| modulus [Pa] | offset [mm] | completed | collisions | finger force [N] | end |",
        "|---|---|---|---|---|---|",
    ]
    for modulus, runs in pinch.items():
        for r in runs:
            lines.append(
                f"| {modulus:g} | {r['offset'] * 1000:.1f} | {'yes' if r['done'] else 'no'} | "
                f"{r['collisions']} | {r['finger_force']:.0f} | {r['end'][:120]} |"
            )
    return "\n".join([*lines, ""])


DROPS_ACROSS = 24  # drops per modulus
WEDGED = 5.0  # a part at rest under contact forces past this many times its weight is wedged


def _modulus_text(modulus: float) -> str:
    """A scenario text setting the default contact material's hydroelastic modulus [Pa]."""
    material = f"{{hydroelastic_modulus: {modulus:g}}}"
    return f"{{scene_graph_config: {{default_proximity_properties: {material}}}}}"


def drops_across_a_pocket(modulus: float) -> tuple[float, list[dict]]:
    """Experiment 5 at hydroelastic `modulus`: the part's weight [N], and per drop its yaw off
    the pocket [rad], its speed [m/s], the part's underside at rest above where it is when
    seated [m] and the largest contact force on the part then [N]."""
    text = _modulus_text(modulus)
    station = make_cell_station(station_scenario(load_cell_scenario(None, [text]), robot=False))
    plant, body = station.plant, station.part_body("oval_flange_1")
    X_W_slot = plant.GetFrameByName("slot_1").CalcPoseInWorld(plant.CreateDefaultContext())
    part_geometries = set(plant.GetCollisionGeometriesForBody(body))
    weight = 9.81 * body.default_mass()
    rng = np.random.default_rng(0)
    drops = []
    for _ in range(DROPS_ACROSS):
        yaw, speed = rng.uniform(0.6, math.pi / 2), rng.uniform(0.5, 1.2)
        (dx, dy), tilt = rng.uniform(-0.01, 0.01, 2), rng.uniform(-0.1, 0.1)
        context = station.create_default_context()
        plant_context = plant.GetMyContextFromRoot(context)
        X = X_W_slot @ RigidTransform(RollPitchYaw(tilt, 0, yaw), [dx, dy, 0.006])
        plant.SetFreeBodyPose(plant_context, body, X)
        plant.SetFreeBodySpatialVelocity(
            plant_context, body, SpatialVelocity([0, 0, 0], [0, 0, -speed])
        )
        Simulator(station.diagram, context).AdvanceTo(1.0)
        results = plant.get_contact_results_output_port().Eval(plant_context)
        largest = 0.0
        for i in range(results.num_hydroelastic_contacts()):
            info = results.hydroelastic_contact_info(i)
            surface = info.contact_surface()
            if {surface.id_M(), surface.id_N()} & part_geometries:
                largest = max(largest, float(np.linalg.norm(info.F_Ac_W().translational())))
        rest = X_W_slot.InvertAndCompose(plant.EvalBodyPoseInWorld(plant_context, body))
        drops.append(
            {"yaw": yaw, "speed": speed, "height": rest.translation()[2], "force": largest}
        )
    return weight, drops


def _drops_report(drops: dict[float, tuple[float, list[dict]]]) -> str:
    weight = next(iter(drops.values()))[0]
    lines = [
        "",
        "## 5. A part dropped across a pocket",
        "",
        f"The oval flange ({weight / 9.81 * 1000:.0f} g) let go 6 mm above slot 1's pocket, "
        "turned 0.6–1.57 rad from it (its boss is longer than the pocket is wide), up to 1 cm "
        "off its centre and 0.1 rad tilted, falling at 0.5–1.2 m/s, as a lost grip drops it; "
        f"workpieces only, {DROPS_ACROSS} seeded drops, 1 s each. *wedged*: drops after which "
        f"the part rests under a contact force past {WEDGED:g} times its weight (its boss "
        "sunk between the pocket's rims); *height*: its underside at rest above where it is "
        "when seated (resting on the rims: 4 mm, less when it lies tilted across them; "
        "wedged: below 0).",
        "",
        "| modulus [Pa] | wedged | largest force at rest [N] | height at rest [mm] |",
        "|---|---|---|---|",
    ]
    for modulus, (weight, runs) in drops.items():
        wedged = sum(r["force"] > WEDGED * weight for r in runs)
        heights = [r["height"] * 1000 for r in runs]
        lines.append(
            f"| {modulus:g} | {wedged}/{len(runs)} | {max(r['force'] for r in runs):.1f} | "
            f"{min(heights):.2f}–{max(heights):.2f} |"
        )
    return "\n".join([*lines, ""])


def _fmt(x: float | None, unit: str = "") -> str:
    return "—" if x is None else f"{x:g}{unit}"


def _report(args, rows, grips, carry, grip) -> str:
    lines = [
        "# Contact settings: settling, friction grasps, real-time factor",
        "",
        f"`python benchmarks/bench_contact.py --repeats {args.repeats}` — drake "
        f"{importlib.metadata.version('drake')}, {platform.machine()}, {os.cpu_count()} cores "
        f"(shared with other work while it ran), Python {platform.python_version()}. Real-time "
        "factors are simulated time over this process's CPU time, best of the repeats.",
        "",
        "## 1. Settling",
        "",
        "Parts let go near their seats (1 mm off, 1° tilt, 3 mm above a plate seat, 6 mm above "
        "a host's row) in three configurations (F1; F3 S12 F01; F1 S23 F03), workpieces only, "
        "1 s. *rest*: when every part is slower than 1 mm/s for good (the slowest of the three "
        "runs; — : not by 1 s); *read*: runs whose configuration the sensor reads; *off*: the "
        "largest horizontal distance of a part to its nominal seat at the end (the pocket's "
        "clearance is 1.5 mm); *at rest*: RTF of the whole station holding still (arm, gripper, "
        "operator's body, parts in the tray), the ratio base of the closed-loop figures.",
        "",
        "| setting | RTF (drops) | rest [s] | read | off [mm] | RTF at rest |",
        "|---|---|---|---|---|---|",
    ]
    for setting, r in rows:
        lines.append(
            f"| {setting.name} | {r['rtf']:.2f} | {_fmt(r['rest'] and round(r['rest'], 2))} | "
            f"{r['read']}/3 | {r['off'] * 1000:.2f} | {r['at_rest']:.2f} |"
        )
    mass = grip.station.part_body("square_flange").default_mass()
    lines += [
        "",
        "## 2. Friction grasps",
        "",
        f"The square flange ({mass:.2f} kg) held in the air by the pads' friction at a grip "
        "force, default contact settings; the tcp accelerates at a steady rate for 50 ms and "
        f"brakes as hard (rates tried: {', '.join(f'{r:g}' for r in RATES)} m/s²). Each cell: "
        "the largest rate at which the part moves less than 1 mm relative to the tcp (— : it "
        "slips at the smallest), and in brackets the tcp's largest measured acceleration at that "
        "rate [m/s²].",
        "",
        "| grip force [N] | up | along the pads | across the pads |",
        "|---|---|---|---|",
    ]
    for force, limits in grips.items():
        cells = [
            f"{_fmt(limits[d][0])} ({limits[d][1]:.0f})"
            for d in ("up", "along the pads", "across the pads")
        ]
        lines.append(f"| {force:g} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## 3. What the carry asks",
        "",
        f"Along row 1's three plans, while a part is held: the largest tcp acceleration "
        f"{carry['largest']:.2f} m/s², the largest upward one {carry['upward']:.2f} m/s² (plans "
        "sampled at 200 Hz).",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
