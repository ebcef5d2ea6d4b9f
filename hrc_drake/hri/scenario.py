"""Scenarios: one typed file for a run — the assembly, the cell, the operator, motion and run
settings, and what the run should show.

A scenario file (`scenarios/*.yaml`) is loaded strictly: a misspelt key or a value of the wrong
type is an error naming it, and keys left out take the defaults below. The cell layer loads the
same schema with Drake's `yaml_load_typed` (`hrc_drake.cell.scenario`); this module reads it
without Drake for the task layer (`react`, `table2`, evaluations). Command-line overrides are
more YAML merged on top (`--scenario-text "{motion: {hold_time: 0.5}}"`).

    name: row8-forces-4-then-8
    description: the operator mounts F3, then S12
    assembly: flange                 # models/assemblies/<name>.yaml, or a path
    table2_row: 8
    operator:
      deviations: [{step: 1, task: F3}, {step: 2, task: S12}]
    expected:
      published: ["1", "4", "8", "4", "1", "2", "7", "10"]
      minimum_effort: ["1", "4", "8", "11"]
    motion: {hold_time: 5.0}         # optional: cell, motion, physics, run, safety, body
    interaction: {mode: wait, interface: touch, delay: {distribution: lognormal, median: 2.5,
                  sigma: 0.3}}       # optional; the delay defaults to the interface's
"""

import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from hrc_drake.hri.activity import Person, vary_person
from hrc_drake.hri.faults import FaultConfig, FaultError, check_faults
from hrc_drake.hri.operator import ScriptedOperator, StochasticOperator, parse_operator_script
from hrc_drake.layout import CellLayout
from hrc_drake.motion.options import MotionOptions
from hrc_drake.paths import not_a_file
from hrc_drake.resources import models_dir, scenarios_dir
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.interaction import (
    DEFAULT_DELAYS,
    DEFAULT_INTERFACE,
    DEFAULT_MODE,
    INTERFACES,
    MODES,
    DelayedIndications,
    IndicationDelay,
    Interaction,
    InteractionError,
    delay_generator,
    make_interaction,
)
from hrc_drake.typed_yaml import TypedYamlError, YamlSyntaxError, load_typed


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message names the file and the key."""


# The source `check_scenario` names when a value came from the command line's YAML overrides.
TEXT_SOURCE = "--scenario-text"


def _check_finite(value, key: str, fail) -> None:
    """Refuse NaN and infinity anywhere in a scenario (YAML's `.nan`, `.inf`): every number of a
    scenario is a quantity of the cell, and a NaN passes every `<` and `>` check below, to fail
    later in Drake (a NaN hold time is an assertion in the planning worker, an infinite one a
    run that never ends)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise fail(key, f"{value} is not a number the cell can use; give a finite number")
    elif dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            _check_finite(getattr(value, f.name), f"{key}.{f.name}" if key else f.name, fail)
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            _check_finite(item, f"{key}[{i}]", fail)
    elif isinstance(value, dict):
        for k, item in value.items():
            _check_finite(item, f"{key}.{k}", fail)


def _check_limits(scenario, fail) -> None:
    """The signs and ranges of the numbers no other check covers: each of these, out of range,
    fails only once the cell is built or the run has started (or never, silently)."""
    if scenario.run.max_steps < 1:
        raise fail("run.max_steps", f"a run takes at least 1 step, got {scenario.run.max_steps}")
    for key in ("robot_uncertainty", "slow_band", "moving_speed"):
        if getattr(scenario.safety, key) < 0:
            raise fail(f"safety.{key}", f"must be >= 0, got {getattr(scenario.safety, key)}")
    arm, rg2, camera = scenario.station.ur3, scenario.station.rg2, scenario.station.camera
    if arm.tracking_tolerance <= 0:
        raise fail("station.ur3.tracking_tolerance", "give an angle > 0 rad (0.05)")
    for key in ("kp", "kd"):
        if any(g < 0 for g in getattr(arm, key)):
            raise fail(f"station.ur3.{key}", "gains are >= 0")
    if not 0 <= rg2.initial_opening <= 0.110:
        raise fail("station.rg2.initial_opening", "the RG2 opens 0 to 0.110 m")
    if rg2.kp <= 0 or rg2.kd < 0:
        raise fail("station.rg2.kp" if rg2.kp <= 0 else "station.rg2.kd", "give kp > 0, kd >= 0")
    if rg2.grip_tolerance <= 0:
        raise fail("station.rg2.grip_tolerance", "give a distance > 0 m (0.004)")
    if camera.width < 1 or camera.height < 1:
        raise fail(
            "station.camera", f"give an image size >= 1 px, got {camera.width}x{camera.height}"
        )
    if not 0 < camera.fov_y < 180:
        raise fail(
            "station.camera.fov_y", f"give a field of view in (0, 180) deg, got {camera.fov_y}"
        )


@dataclass
class Deviation:
    """At decision `step` (from 1) the operator performs `task` instead of the proposal."""

    step: int = 0
    task: str = ""


@dataclass
class OperatorConfig:
    """Who the operator is: scripted deviations, or a seeded stochastic operator.

    Attributes:
        deviations: scripted tasks performed instead of the robot's proposal.
        override_prob: probability of performing another feasible task (stochastic).
        mistake_prob: probability of misplacing a part the spec lists under `mistakes`.
        seed: seed of the stochastic operator.
        model: a named operator model (`hrc_drake.hri.populations`), with `params`.
        params: parameters of `model` (numbers, or text such as habitual's `order: S23`).
        delay_seed: where the indication delays are drawn from: empty, the operator's own
            stream (`operator_delays(seed)`); `[S, i]`, those of run i of an evaluation seeded
            S (`delay_generator(S, i)`), so that one run of `evaluate --cell` replays alone.
    """

    deviations: list[Deviation] = field(default_factory=list)
    override_prob: float = 0.0
    mistake_prob: float = 0.0
    seed: int = 0
    model: str = ""
    params: dict[str, float | str] = field(default_factory=dict)
    delay_seed: list[int] = field(default_factory=list)


@dataclass
class DeciderConfig:
    """A decider (`hrc_drake.tasks.deciders`) proposing at every task boundary instead of the
    scenario's policy, learning from what the cell observed (as in `evaluate --cell`).

    Attributes:
        name: one of `hrc_drake.tasks.deciders.DECIDERS`; empty, the scenario's `policy`.
        seed: the decider's seed (the evaluation's `--seed`).
        costs: a cost table file (`hrc-drake costs`); empty, the cell's (computed once, cached).
    """

    name: str = ""
    seed: int = 0
    costs: str = ""


@dataclass
class Expected:
    """What a run should show, as the spec's state names (Table 2's columns)."""

    published: list[str] = field(default_factory=list)
    minimum_effort: list[str] = field(default_factory=list)


_MOTION = MotionOptions()  # the defaults live there (Drake-free module)


@dataclass
class MotionConfig:
    """Motion-layer settings a scenario may change (the rest: `motion.options.MotionOptions`).

    Attributes:
        hold_time: seconds the robot holds a placed part while the operator bolts it.
        tcp_speed_limit: m/s; 0.25 is ISO 10218-1's reduced speed.
        approach_distance: m; pre-grasp / pre-place offset along the tool's approach axis.
        seed: seed of the random IK starts.
    """

    hold_time: float = _MOTION.hold_time
    tcp_speed_limit: float = _MOTION.tcp_speed_limit
    approach_distance: float = _MOTION.approach_distance
    seed: int = _MOTION.seed


@dataclass
class ContactConfig:
    """The contact material of every collision geometry whose model does not set its own: the
    one place these figures are stated (the station hands them to Drake as SceneGraphConfig's
    `default_proximity_properties`, and the friction to every geometry but the gripper's).
    A model states only what differs: the gripper's rigid housing and fingers and its pads'
    rubber. The plate, the tray and the table stay compliant although they never move: a part
    dropped a few mm onto a rigid seat is thrown out of it. The choices are calibrated in
    benchmarks/reports/contact.md (`benchmarks/bench_contact.py`).

    Attributes:
        hydroelastic_modulus: Pa, of compliant geometry (the parts, the arm's links). Half of
            Drake's default 1e7 ("Default Contact Parameters": sub-millimetre penetrations for
            household-sized objects; the hydroelastic user guide: 1e8 and above seldom used):
            at 1e7 and 10 ms a part pressed by the rigid fingers onto a pocket's rim bursts
            out of the grasp (docs/station.md, "Contact settings").
        resolution_hint: m, the mesh size of compliant geometry that needs one (cylinders,
            capsules; boxes ignore it).
        margin: m, Drake's hydroelastic margin (its recommended 1e-4): speculative contact
            constraints a little before touching, so that a part let go on its seat does not
            fall into it for a step before the contact pushes back.
        relaxation_time: s, the dissipation of SAP (Drake's linear Kelvin-Voigt model, the one
            the default `sap` approximation uses): a compliant contact creeps to rest with this
            time constant, so a short one rests a released part within a few steps.
        hunt_crossley_dissipation: s/m, the dissipation of the `similar` and `lagged`
            approximations only (SAP ignores it).
        static_friction, dynamic_friction: Coulomb friction coefficients.
    """

    hydroelastic_modulus: float = 5.0e6
    resolution_hint: float = 0.01
    margin: float = 1.0e-4
    relaxation_time: float = 0.001
    hunt_crossley_dissipation: float = 10.0
    static_friction: float = 0.6
    dynamic_friction: float = 0.5


@dataclass
class PhysicsConfig:
    """The MultibodyPlant's settings (the names of Drake's `MultibodyPlantConfig`).

    The defaults are calibrated (benchmarks/reports/contact.md, cell.md): with the contact
    material below (a 1 ms relaxation time and Drake's 0.1 mm margin), 10 ms rests parts let go
    near their seats within 0.12 s and the sensor reads every configuration, at twice the
    real-time factor of 5 ms (the earlier 10 ms failure was the 0.1 s relaxation time and no
    margin); `sap` rests the 67 g oval flange in its pocket where `lagged`/`similar` leave it
    chattering (0.4 N of its 0.66 N weight carried, 9 mm/s left after 2 s, at 5 ms), at the
    same cost. The bolts' weld constraints need a SAP-family approximation.
    """

    time_step: float = 1e-2
    contact_model: str = "hydroelastic_with_fallback"
    discrete_contact_approximation: str = "sap"
    contact_surface_representation: str = "polygon"
    contact: ContactConfig = field(default_factory=ContactConfig)


@dataclass
class RunConfig:
    """Timing of the closed loop.

    Attributes:
        period: the Supervisor's update period [s].
        settle_time: after a task, how long the parts settle before the cell is read [s].
        max_sim_time: a run that has not ended by then is a failure [s].
        max_steps: decision steps before a run is a failure.
        plan_ahead: while the operator bolts, plan the task the policy will propose next, so
            that the plan is ready at the task boundary (no robot idle time on the planner).
        wait_for_planner: simulated time stands still while the planner works, so that a run
            does not depend on the machine's speed (same seed, same result); False: time runs
            on and the robot holds still meanwhile, as on a real cell (live runs always).
        indication_timeout: seconds the robot waits for the operator's indication before it
            notes the silence and asks again (holding still meanwhile); it asks again every
            `indication_timeout` seconds.
        indication_give_up: simulated seconds after a question was first asked (a `CHOOSE`,
            or a `HANDOVER` to confirm) with no answer, when the robot gives up: the run ends,
            not terminal, with the reason (a live prompt nobody answers, or whose click was
            lost, never leaves a run looping). Simulated time: a live run is paced at real time
            or slower, so it is at least as long on the wall clock.
        handover_time: seconds the simulated operator takes to do a task handed over to them
            by hand (fetch the part, put it in its seat) before bolting it
            (`motion.hold_time`); a person in the browser takes their own time.
        recover_tries: how often, within one task, the robot picks its part again from where
            it lies (a part that slipped out of the gripper, or was let go out of its seat)
            before it hands the task over to the operator.
        path_timeout: seconds the robot waits for a path that an obstacle blocks (holding
            still, planning again whenever the obstacle moves or goes) before it hands the task
            over to the operator.
    """

    period: float = 0.02
    settle_time: float = 0.3
    max_sim_time: float = 900.0
    max_steps: int = 30
    plan_ahead: bool = True
    wait_for_planner: bool = True
    indication_timeout: float = 10.0
    indication_give_up: float = 120.0
    handover_time: float = 5.0
    recover_tries: int = 2
    path_timeout: float = 10.0


@dataclass
class SafetyConfig:
    """Speed and separation monitoring (ISO/TS 15066 5.5.4): S_p = v_h (T_r + T_s) + v_r T_r +
    S_s + C + Z_d + Z_r, at every Supervisor update.

    Attributes:
        enabled: monitor the separation and scale the robot's speed (off: the robot ignores the
            operator's body, which is still drawn and measured).
        human_speed: v_h [m/s] when the body is not tracked (ISO/TS 15066 5.5.4.2.3 and
            ISO 13855: 1.6 m/s for a person whose speed is not monitored).
        track_human_speed: the simulated body is tracked exactly: v_h is its measured speed
            toward the robot (the TS allows a monitored speed); off, `human_speed` throughout.
        reaction_time: T_r [s], the robot's reaction time (0.1 s is a common assumption).
        intrusion: C [m]; 0 when the distance is taken to the body itself.
        human_uncertainty: Z_d [m], the body's position uncertainty (a tracked hand).
        robot_uncertainty: Z_r [m]; 0 for the simulated robot.
        slow_band: m above S_p within which the robot already slows down.
        moving_speed: rad/s; a robot joint faster than this counts as moving (violations).
        separation: `predictive` (the robot times its moves around where it forecasts the
            operator's body, monitoring underneath) or `reactive` (monitoring alone).
        departure: m; the observed hand this far from the forecast makes the robot forecast
            again and re-time its moves.
        max_wait: the longest a move is held back for the operator [s].
        forecast_spread: how much of its timing spread the forecast keeps (1: all of it; 0: it
            takes the person's modelled timing as exact, the bound that a perfect forecast of a
            person who behaves as modelled would reach;
            `hrc_drake.cell.controller.forecast.OperatorForecast`).
    """

    enabled: bool = True
    human_speed: float = 1.6
    track_human_speed: bool = True
    reaction_time: float = 0.1
    intrusion: float = 0.0
    human_uncertainty: float = 0.05
    robot_uncertainty: float = 0.0
    slow_band: float = 0.05
    moving_speed: float = 0.01
    separation: str = "predictive"
    departure: float = 0.15
    max_wait: float = 6.0
    forecast_spread: float = 1.0


_PERSON = Person()  # the defaults live there (Drake-free module)


@dataclass
class BodyConfig:
    """The operator's kinematic body (hand, forearm, upper arm, torso, head) beside the table, and
    what it does (`hrc_drake.hri.activity`).

    Attributes:
        enabled: put the body in the scene (off: no body, no monitoring).
        activity: `bolting` (the hand reaches in only to bolt the held part: the Table 2 rows'
            operator) or `desk` (it also points at the target seat and fetches bolts and nuts
            from the layout's bins, sharing the desk with the robot).
        stance: [x, y] of the operator's torso axis in world [m] (the table edge is x = 0.75).
        rest_hand: [x, y, z] of the waiting hand in world [m].
        reach_offset: [x, y, z] of the hand from the held part while bolting [m].
        hand_speed: the hand's peak speed [m/s].
        reach_time: seconds of the reach and of the withdrawal (shortened to fit the hold).
        reach: m from shoulder to hand centre with the arm stretched (the person may also lean
            `hrc_drake.hri.activity.LEAN` toward the table).
        left_handed: works with the left hand.
        fetch_lag: seconds at rest between pointing and fetching (`desk`).
        grab_time: seconds in a bin per handful (`desk`).
        handful: bolts or nuts taken per grab (`desk`).
        point_time: seconds the hand points over the target seat (`desk`).
        spread: each operator seed draws its own person around these values (0: this person;
            `hrc_drake.hri.activity.vary_person`).
    """

    enabled: bool = True
    activity: str = "bolting"
    stance: list[float] = field(default_factory=lambda: list(_PERSON.stance))
    rest_hand: list[float] = field(default_factory=lambda: list(_PERSON.rest_hand))
    reach_offset: list[float] = field(default_factory=lambda: list(_PERSON.reach_offset))
    hand_speed: float = _PERSON.hand_speed
    reach_time: float = _PERSON.reach_time
    reach: float = _PERSON.reach
    left_handed: bool = _PERSON.left_handed
    fetch_lag: float = _PERSON.fetch_lag
    grab_time: float = _PERSON.grab_time
    handful: int = _PERSON.handful
    point_time: float = _PERSON.point_time
    spread: float = 0.0

    def person(self, seed: int | None = None) -> Person:
        """The person these values describe; with an operator `seed`, the one drawn for it."""
        person = Person(
            stance=(self.stance[0], self.stance[1]),
            rest_hand=tuple(self.rest_hand),
            hand_speed=self.hand_speed,
            reach=self.reach,
            left_handed=self.left_handed,
            fetch_lag=self.fetch_lag,
            grab_time=self.grab_time,
            handful=self.handful,
            point_time=self.point_time,
            reach_offset=tuple(self.reach_offset),
            reach_time=self.reach_time,
        )
        return person if seed is None else vary_person(person, seed, self.spread)


@dataclass
class ArmConfig:
    """The UR3 in the station: where it starts, its simulated joint servo, and the tracking check
    of the controller.

    Attributes:
        initial_positions: joint positions at the start [rad] (UR3_JOINTS order); empty: the
            motion layer's home posture, where every plan starts and ends.
        ready: a posture above the work used when no motion layer is asked (stills, cell tests).
        kp, kd: the simulated servo's PD gains per joint [N·m/rad, N·m·s/rad]; stiff, because SAP
            integrates them implicitly; the arm's own gravity is compensated (as a UR's controller
            does), so they only reject a held part's weight and contact forces.
        tracking_tolerance: rad; a measured joint farther than this from its command stops the
            task (the arm was pushed, or it is blocked).
    """

    initial_positions: list[float] = field(default_factory=list)
    ready: list[float] = field(default_factory=lambda: [0.0, -1.7, 1.9, -1.77, -1.5708, 0.0])
    kp: list[float] = field(default_factory=lambda: [4000.0, 4000.0, 2000.0, 500.0, 500.0, 500.0])
    kd: list[float] = field(default_factory=lambda: [200.0, 200.0, 100.0, 20.0, 20.0, 20.0])
    tracking_tolerance: float = 0.05


@dataclass
class GripperConfig:
    """The RG2-like gripper in the station and the controller's grasp check.

    Attributes:
        initial_opening: opening between the finger insides at the start and between tasks [m]
            (0.8 of the 0.110 m stroke).
        grip_force: N, the gripping force the controller commands (the RG2 takes 3-40 N); the
            part is carried by the pads' friction alone. 20 N holds the heaviest part of the
            flange case (the 0.57 kg square flange, 5.6 N) with a margin of 4.8 at rest
            (benchmarks/reports/contact.md: the largest carry acceleration without slip).
        kp, kd: the simulated finger servo's PD gains [N/m, N·s/m]; the servo pushes with at
            most the commanded force (`hrc_drake.cell.station.gripper.FingerServo`), and with all
            of it once a finger stalls `force / kp` short of its target: 40 N (the RG2's most) at
            the 1 mm each finger is commanded past the part (`motion.options.grip_squeeze`, 2 mm).
        grip_tolerance: m; a measured opening farther than this from the width of the part the
            gripper should hold means it holds nothing (or something else).
    """

    initial_opening: float = 0.088
    grip_force: float = 20.0
    kp: float = 40000.0
    kd: float = 40.0
    grip_tolerance: float = 0.004


@dataclass
class CameraSettings:
    """An RGB camera looking at the cell from the operator's side (stills).

    Attributes:
        enabled: add the camera (`--still` turns it on).
        position, target: where it stands and what it looks at, in world [m].
        width, height: image size [px]; fov_y: vertical field of view [deg].
    """

    enabled: bool = False
    position: list[float] = field(default_factory=lambda: [0.95, -0.75, 0.80])
    target: list[float] = field(default_factory=lambda: [0.17, -0.06, 0.14])
    width: int = 1024
    height: int = 640
    fov_y: float = 40.0


@dataclass
class StationConfig:
    """What the simulated station holds beyond the assembly's models.

    Attributes:
        robot: add the UR3 and the gripper (False: the workpieces only, for fast cell tests).
        initial_placements: part instance -> a task token (`F1`, `S23`, `F02`) or `tray`; parts
            not named start in the tray.
        ur3, rg2, camera: see their types.
    """

    robot: bool = True
    initial_placements: dict[str, str] = field(default_factory=dict)
    ur3: ArmConfig = field(default_factory=ArmConfig)
    rg2: GripperConfig = field(default_factory=GripperConfig)
    camera: CameraSettings = field(default_factory=CameraSettings)


@dataclass
class DelayConfig:
    """The indication delay (`hrc_drake.tasks.interaction.IndicationDelay`): `fixed` at `median`
    seconds, or `lognormal` with that median and `sigma`, the standard deviation of its log."""

    distribution: str = "lognormal"
    median: float = DEFAULT_DELAYS[DEFAULT_INTERFACE].median
    sigma: float = DEFAULT_DELAYS[DEFAULT_INTERFACE].sigma


@dataclass
class InteractionConfig:
    """How the operator's indication reaches the robot (`hrc_drake.tasks.interaction`).

    Attributes:
        mode: `anticipate` (the robot may start on its prediction) or `wait` (it waits for the
            indication). `evaluate --cell` plays `--interaction` over it.
        interface: `pointer`, `gesture` or `touch` (the paper's section 5).
        delay: the indication delay; left out, the interface's default (our assumption, see
            `DEFAULT_DELAYS`).
    """

    mode: str = DEFAULT_MODE
    interface: str = DEFAULT_INTERFACE
    delay: DelayConfig | None = None


@dataclass
class Scenario:
    """One run of the cell (or of the decision loop): see the module docstring.

    `cell` is the cell's layout; left out, the assembly spec's `cell:` section (or the default
    layout) is used. `policy` is a policy file; empty, the exact minimum-effort policy; a
    `decider` replaces it.
    """

    name: str = ""
    description: str = ""
    assembly: str = "flange"
    policy: str = ""
    table2_row: int | None = None
    operator: OperatorConfig = field(default_factory=OperatorConfig)
    decider: DeciderConfig = field(default_factory=DeciderConfig)
    expected: Expected = field(default_factory=Expected)
    cell: CellLayout | None = None
    motion: MotionConfig = field(default_factory=MotionConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    run: RunConfig = field(default_factory=RunConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    station: StationConfig = field(default_factory=StationConfig)
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    faults: list[FaultConfig] = field(default_factory=list)

    @property
    def assembly_path(self) -> Path:
        """The assembly spec file: `assembly` as a path, or a name under models/assemblies/."""
        path = Path(self.assembly)
        # A path to something that exists is that path, suffix or not (`--assembly /dev/null`
        # is then reported as the device it is, not as a missing /dev/null.yaml).
        if path.suffix or (os.sep in self.assembly and path.exists()):
            return path
        return models_dir() / "assemblies" / f"{self.assembly}.yaml"

    @property
    def script(self) -> dict[int, str]:
        """The scripted deviations as decision step -> task."""
        return {d.step: d.task for d in self.operator.deviations}

    @property
    def published(self) -> tuple[str, ...]:
        """Table 2's published sequence (state names)."""
        return tuple(self.expected.published)

    @property
    def minimum_effort(self) -> tuple[str, ...]:
        """The minimum-effort sequence (state names)."""
        return tuple(self.expected.minimum_effort)

    @property
    def stochastic(self) -> bool:
        """Whether the operator deviates at random."""
        return self.operator.override_prob > 0 or self.operator.mistake_prob > 0

    def operator_for(self, space: StateSpace):
        """The operator this scenario describes, for the decision loop or the cell; its
        indications come after the interaction's delay (`DelayedIndications`, seeded with the
        operator's seed: the simulated station waits `indication_delay(step)`)."""
        op = self.operator
        if op.model:
            from hrc_drake.hri.populations import make_operator_model

            answers = make_operator_model(op.model, space, seed=op.seed, **op.params)
        elif self.stochastic:
            answers = StochasticOperator(space, op.override_prob, op.mistake_prob, op.seed)
        else:
            answers = ScriptedOperator(self.script)
        delay = self.interaction_model().delay
        if op.delay_seed:
            rng = delay_generator(*op.delay_seed)
            return DelayedIndications(answers, delay, rng=rng)
        return DelayedIndications(answers, delay, op.seed)

    def interaction_model(self) -> Interaction:
        """The `interaction` section as a checked `Interaction`."""
        it = self.interaction
        delay = None
        if it.delay is not None:
            delay = IndicationDelay(it.delay.distribution, it.delay.median, it.delay.sigma)
        return make_interaction(it.mode, it.interface, delay)


def check_scenario(scenario: Scenario, source: str) -> Scenario:
    """Value checks the types cannot express; ScenarioError naming the key."""

    where = source if source == TEXT_SOURCE else f"scenario {source}"

    def fail(key: str, problem: str) -> ScenarioError:
        return ScenarioError(f"{where}: {key}: {problem}")

    _check_finite(scenario, "", fail)
    _check_limits(scenario, fail)

    op = scenario.operator
    for key in ("override_prob", "mistake_prob"):
        value = getattr(op, key)
        if not 0.0 <= value <= 1.0:
            raise fail(f"operator.{key}", f"a probability is within [0, 1], got {value}")
    steps = set()
    for i, d in enumerate(op.deviations):
        if d.step < 1:
            raise fail(f"operator.deviations[{i}].step", f"steps count from 1, got {d.step}")
        if not d.task:
            raise fail(f"operator.deviations[{i}].task", "name a task, e.g. F3 or undo")
        if d.step in steps:
            raise fail(f"operator.deviations[{i}]", f"step {d.step} is given twice")
        steps.add(d.step)
    if op.deviations and (scenario.stochastic or op.model):
        raise fail("operator", "give scripted deviations or a stochastic operator, not both")
    if op.delay_seed and len(op.delay_seed) != 2:
        raise fail(
            "operator.delay_seed",
            f"give [evaluation seed, run], e.g. [0, 3], or leave it out; got {op.delay_seed}",
        )
    _check_decider(scenario.decider, fail)
    for key in ("hold_time", "approach_distance"):
        if getattr(scenario.motion, key) < 0:
            raise fail(f"motion.{key}", "must be >= 0")
    if scenario.motion.tcp_speed_limit <= 0:
        raise fail(
            "motion.tcp_speed_limit",
            f"the robot cannot move at {scenario.motion.tcp_speed_limit} m/s; give a speed > 0 "
            "(0.25: ISO 10218-1's reduced speed)",
        )
    contact = scenario.physics.contact
    for key in ("hydroelastic_modulus", "resolution_hint"):
        if getattr(contact, key) <= 0:
            raise fail(f"physics.contact.{key}", "must be > 0")
    for key in ("margin", "relaxation_time", "hunt_crossley_dissipation", "dynamic_friction"):
        if getattr(contact, key) < 0:
            raise fail(f"physics.contact.{key}", "must be >= 0")
    if contact.static_friction < contact.dynamic_friction:
        raise fail("physics.contact.static_friction", "must be >= dynamic_friction")
    if scenario.physics.time_step <= 0:
        raise fail("physics.time_step", "the cell is a discrete plant: give a step > 0 (1e-2)")
    for key in ("period", "settle_time", "max_sim_time", "indication_timeout", "path_timeout"):
        if getattr(scenario.run, key) <= 0:
            raise fail(f"run.{key}", "must be > 0")
    give_up = scenario.run.indication_give_up
    if not (math.isfinite(give_up) and give_up > 0):
        raise fail("run.indication_give_up", f"give finite seconds > 0, got {give_up}")
    handover = scenario.run.handover_time
    if not (math.isfinite(handover) and handover >= 0):
        raise fail("run.handover_time", f"give finite seconds >= 0, got {handover}")
    if scenario.run.recover_tries < 0:
        raise fail("run.recover_tries", "must be >= 0 (0: hand every lost part over)")
    for key in ("human_speed", "reaction_time", "intrusion", "human_uncertainty"):
        if getattr(scenario.safety, key) < 0:
            raise fail(f"safety.{key}", "must be >= 0")
    for key in ("stance", "rest_hand", "reach_offset"):
        want = 2 if key == "stance" else 3
        if len(getattr(scenario.body, key)) != want:
            raise fail(f"body.{key}", f"give {want} coordinates in metres")
    if not 3.0 <= scenario.station.rg2.grip_force <= 40.0:
        raise fail("station.rg2.grip_force", "the RG2 grips with 3 to 40 N")
    if scenario.cell is not None:
        try:
            scenario.cell.check("cell")
        except ValueError as err:
            raise ScenarioError(f"{where}: {err}") from err
    _check_body(scenario, fail)
    _check_separation(scenario.safety, fail)
    _check_interaction(scenario.interaction, fail)
    try:
        check_faults(scenario.faults, source)
    except FaultError as err:
        raise ScenarioError(str(err)) from err
    return scenario


def _check_decider(decider: DeciderConfig, fail) -> None:
    """A known decider name (or none)."""
    from hrc_drake.tasks.deciders import DECIDERS

    if decider.name and decider.name not in DECIDERS:
        known = ", ".join(DECIDERS)
        raise fail("decider.name", f"unknown decider {decider.name!r}; use one of {known}")


SEPARATION_MODES = ("predictive", "reactive")
ACTIVITIES = ("bolting", "desk")


def _check_separation(safety: SafetyConfig, fail) -> None:
    """The separation mode and the forecast's bounds."""
    if safety.separation not in SEPARATION_MODES:
        raise fail(
            "safety.separation",
            f"unknown mode {safety.separation!r}; use {' or '.join(SEPARATION_MODES)}",
        )
    if safety.departure <= 0:
        raise fail("safety.departure", f"give a distance > 0 m, got {safety.departure}")
    if safety.max_wait < 0:
        raise fail("safety.max_wait", f"give seconds >= 0, got {safety.max_wait}")
    if not 0.0 <= safety.forecast_spread <= 1.0:
        raise fail(
            "safety.forecast_spread", f"give a fraction in [0, 1], got {safety.forecast_spread}"
        )


def _check_body(scenario: Scenario, fail) -> None:
    """The operator's body: its values, and bins its hand reaches (with either hand, when
    persons vary)."""
    body = scenario.body
    if not 0 < body.hand_speed <= 2.0:
        raise fail("body.hand_speed", "give a speed in (0, 2] m/s (1.6 m/s: ISO 13855)")
    if body.activity not in ACTIVITIES:
        raise fail("body.activity", f"unknown activity {body.activity!r}; use one of {ACTIVITIES}")
    for key in ("reach", "reach_time"):
        if getattr(body, key) <= 0:
            raise fail(f"body.{key}", f"must be > 0, got {getattr(body, key)}")
    for key in ("fetch_lag", "grab_time", "point_time"):
        if getattr(body, key) < 0:
            raise fail(f"body.{key}", f"give seconds >= 0, got {getattr(body, key)}")
    if body.handful < 1:
        raise fail("body.handful", f"a hand takes at least 1 bolt per grab, got {body.handful}")
    if not 0 <= body.spread <= 0.5:
        raise fail("body.spread", f"give a fraction in [0, 0.5], got {body.spread}")
    if body.activity != "desk" or not body.enabled:
        return
    layout = scenario.cell
    if layout is None:
        from hrc_drake.layout import layout_from
        from hrc_drake.tasks.spec import SpecError, load_spec

        try:
            layout = layout_from(load_spec(scenario.assembly_path).cell)
        except (SpecError, OSError, ValueError):
            return  # the spec's own errors are reported where it is loaded
    person = body.person()
    hands = [person]
    if body.spread > 0:
        hands.append(dataclasses.replace(person, left_handed=not person.left_handed))
    for i, b in enumerate(layout.bins):
        for hand in hands:
            if not hand.reaches(b.grab_point()):
                side = "left" if hand.left_handed else "right"
                raise fail(
                    f"cell.bins[{i}]",
                    f"bin {b.name!r} at {b.position} is out of the operator's {side} hand's "
                    f"reach ({body.reach} m from the shoulder, standing at {body.stance}); "
                    "move it toward the operator",
                )


def _check_interaction(it: InteractionConfig, fail) -> None:
    """The `interaction` section: a known mode and interface, a valid delay."""
    if it.mode not in MODES:
        raise fail("interaction.mode", f"unknown mode {it.mode!r}; use one of {', '.join(MODES)}")
    if it.interface not in INTERFACES:
        raise fail(
            "interaction.interface",
            f"unknown interface {it.interface!r}; use one of {', '.join(INTERFACES)}",
        )
    if it.delay is not None:
        delay = IndicationDelay(it.delay.distribution, it.delay.median, it.delay.sigma)
        try:
            delay.check("delay")
        except InteractionError as err:
            key, _, problem = str(err).partition(": ")
            raise fail(f"interaction.{key}", problem) from None


def scenario_file(name_or_path: str | Path) -> Path:
    """The file of a scenario: a path, or a name under scenarios/; ScenarioError if missing, or
    if what is there is not a regular file (a folder, a device such as /dev/null, a pipe)."""
    path = Path(name_or_path)
    # A name without a suffix is a scenario of the catalogue, unless it is a path to something
    # that exists (`--scenario /bin/ls`): then say what that is, not "not found".
    if not path.suffix and not (os.sep in str(name_or_path) and path.exists()):
        path = scenarios_dir() / f"{name_or_path}.yaml"
    if path.exists() and not path.is_file():
        raise ScenarioError(
            f"scenario {name_or_path}: {not_a_file(path)}; give a scenario YAML file or the "
            "name of one in scenarios/"
        )
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenarios_dir().glob("*.yaml")))
        raise ScenarioError(f"scenario {name_or_path!r} not found; known scenarios: {known}")
    return path


def load_scenario(
    name_or_path: str | Path | None = None, scenario_text: str | Sequence[str] | None = None
) -> Scenario:
    """Load a scenario file (a path, or a name under scenarios/), then the YAML overrides in
    `scenario_text` (one text, or several applied in turn); with no file, the overrides on top
    of the defaults. Strict: ScenarioError naming the key and the expected type for an unknown
    key or a value of the wrong type, and the line and column of a YAML syntax error."""
    scenario, source = Scenario(), "<defaults>"
    if name_or_path is not None:
        path = scenario_file(name_or_path)
        source = str(path)
        scenario = _load_typed(_read_text(path), f"scenario {path}", None)
        if not scenario.name:
            scenario.name = path.stem
    texts = [scenario_text] if isinstance(scenario_text, str) else list(scenario_text or ())
    base = scenario
    for text in texts:
        scenario = _load_typed(text, "--scenario-text", scenario)
    if scenario is base:
        return check_scenario(scenario, source)
    return _check_overridden(base, scenario, source)


def _check_overridden(base: Scenario, scenario: Scenario, source: str) -> Scenario:
    """`check_scenario` of `scenario`, the file `base` with `--scenario-text` over it. A problem
    the file alone shows is the file's; any other came from the text, and the message names
    `--scenario-text` (the user looks there, not in a file they did not touch)."""
    try:
        return check_scenario(scenario, source)
    except ScenarioError as err:
        try:
            check_scenario(base, source)
        except ScenarioError as own:
            if str(own) == str(err):
                raise
        check_scenario(scenario, TEXT_SOURCE)  # the same problem, blamed on the text
        raise  # not reached: the check above raises the same problem


def _read_text(path: Path) -> str:
    """The text of the scenario file `path`; ScenarioError if it cannot be read or is not text
    (`--scenario /bin/ls`)."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(
            f"scenario {path}: not a text file (byte {err.object[err.start]:#04x} at offset "
            f"{err.start} is not UTF-8); give a scenario YAML file"
        ) from None
    except OSError as err:
        raise ScenarioError(
            f"scenario {path}: cannot be read ({err.strerror or err}); give a readable file"
        ) from None


def _load_typed(text: str, source: str, defaults: Scenario | None) -> Scenario:
    try:
        return load_typed(Scenario, text=text, defaults=defaults, source=source)
    except YamlSyntaxError as err:
        raise ScenarioError(str(err)) from None
    except TypedYamlError as err:
        raise ScenarioError(f"{source}: {err}") from None


def with_operator_script(scenario: Scenario, script: str) -> Scenario:
    """A copy whose operator follows the command-line script ``"1:F3,2:S12"``."""
    steps = parse_operator_script(script)
    operator = OperatorConfig(deviations=[Deviation(k, t) for k, t in sorted(steps.items())])
    return dataclasses.replace(scenario, operator=operator)


def table2_scenarios() -> list[Scenario]:
    """The scenarios that reproduce the rows of the paper's Table 2, in the table's order."""
    rows = [load_scenario(p) for p in sorted(scenarios_dir().glob("*.yaml"))]
    rows = [r for r in rows if r.table2_row is not None]
    return sorted(rows, key=lambda r: r.table2_row)
