"""The scenario schema: one typed file for a run — the assembly, the cell, the operator, motion
and run settings, and what the run should show.

A scenario file (`scenarios/*.yaml`) is loaded strictly: a misspelt key or a value of the wrong
type is an error naming it, and keys left out take the defaults below. `hrc_drake.scenario.load`
reads it, without Drake, for the task layer and the cell alike, as Drake's `yaml_load_typed`
would. Command-line overrides are more YAML merged on top
(`--scenario-text "{motion: {hold_time: 0.5}}"`).

    name: row8-forces-4-then-8
    description: the operator mounts F3, then S12
    assembly: flange                 # models/assemblies/<name>.yaml, or a path
    table2_row: 8
    operator:
      deviations: [{step: 1, task: F3}, {step: 2, task: S12}]
    expected:
      published: ["1", "4", "8", "4", "1", "2", "7", "10"]
      minimum_effort: ["1", "4", "8", "11"]
    motion: {hold_time: 5.0}         # optional: cell, motion, run, safety, body,
                                     # station, drivers (hrc_drake.scenario.drivers),
                                     # sensors (hrc_drake.scenario.sensors)
    plant_config: {time_step: 0.01}  # optional: Drake's own configs (DRAKE_SECTIONS)
    interaction: {mode: wait, interface: touch, delay: {distribution: lognormal, median: 2.5,
                  sigma: 0.3}}       # optional; the delay defaults to the interface's
"""

import os
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from hrc_drake.hri.activity import Person, vary_person
from hrc_drake.hri.faults import FaultConfig
from hrc_drake.hri.operator import ScriptedOperator, StochasticOperator
from hrc_drake.layout import CellLayout
from hrc_drake.motion.options import MotionOptions
from hrc_drake.resources import models_dir
from hrc_drake.scenario.drivers import DriversConfig
from hrc_drake.scenario.safety import (
    SafetyConfig,
)
from hrc_drake.scenario.sensors import Preset, SensorsConfig
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.interaction import (
    DEFAULT_DELAYS,
    DEFAULT_INTERFACE,
    DEFAULT_MODE,
    DelayedIndications,
    IndicationDelay,
    Interaction,
    delay_generator,
    make_interaction,
)


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message names the file and the key."""


def known_assemblies() -> list[str]:
    """The names of the assembly specs under models/assemblies/, sorted."""
    return sorted(p.stem for p in (models_dir() / "assemblies").glob("*.yaml"))


def assembly_file(name_or_path: str | Path) -> Path:
    """The assembly spec file of a scenario's `assembly:` and of every command's `--assembly`
    (one rule for both): a path (one with a suffix, or with a folder that exists) as given,
    else the name of a spec under models/assemblies/ (`four-slot`). SpecError for a name that
    is none of those, listing the known names; a missing path is `load_spec`'s to report."""
    text = str(name_or_path)
    path = Path(text)
    # A path to something that exists is that path, suffix or not (`--assembly /dev/null`
    # is then reported as the device it is, not as a missing /dev/null.yaml).
    if path.suffix or (os.sep in text and path.exists()):
        return path
    named = models_dir() / "assemblies" / f"{text}.yaml"
    if os.sep not in text and not named.is_file():
        raise SpecError(
            f"assembly {text!r} not found; known assemblies: {', '.join(known_assemblies())} "
            "(models/assemblies/), or give the path to a spec .yaml"
        )
    return named


# The source `check_scenario` names when a value came from the command line's YAML overrides.
TEXT_SOURCE = "--scenario-text"


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
        tcp_speed_limit: m/s; 0.25 is ISO 10218-1's reduced speed; at most 7.5, the fastest
            the UR3's joints move its TCP (`hrc_drake.scenario.check.UR3_TCP_SPEED_MAX`).
        approach_distance: m; pre-grasp / pre-place offset along the tool's approach axis.
        seed: seed of the random IK starts.
    """

    hold_time: float = _MOTION.hold_time
    tcp_speed_limit: float = _MOTION.tcp_speed_limit
    approach_distance: float = _MOTION.approach_distance
    seed: int = _MOTION.seed


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
        place_guard: N; the guarded descent of a place: while the tool is more than 1 mm above
            its place, a rise of the wrist load against the approach (`ur3.tcp_force`) past this
            stops the descent, backs off and lets the part go (`docs/station.md`, "Guarded
            descent"). 0: no guard, the arm presses on to the plan's place.
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
    place_guard: float = 8.0


class Activity(StrEnum):
    """`body.activity`: what the operator's body does."""

    BOLTING = "bolting"  # reaches in only to bolt the held part
    DESK = "desk"  # also points at the seat and fetches bolts and nuts from the bins


class Behaviour(StrEnum):
    """`body.behaviour`: how the simulated desk operator does the activity."""

    MODELLED = "modelled"  # as the activity model says: the forecast's own family
    UNSEEN = "unseen"  # outside it (`hrc_drake.hri.unseen`); the forecast does not know


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
        behaviour: with `desk`, how the simulated operator does it: `modelled` (the activity
            model, the family the controller's forecast is drawn from) or `unseen` (a person
            outside it, drawn for the operator seed: other speeds and lags, hesitations, changes
            of mind mid-reach, a second fetch; `hrc_drake.hri.unseen`). Only the simulated body
            follows it: the forecast keeps modelling the ordinary person.
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
    activity: str = Activity.BOLTING.value
    behaviour: str = Behaviour.MODELLED.value
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
            (benchmarks/reports/contact.md: the largest carry acceleration without slip,
            measured with the earlier prismatic fingers; the RG2's linkage adds the part's
            weight to the squeeze, `rg2_kinematics.pad_travel_rate`).
        kp, kd: the simulated finger servo's PD gains per finger [N/m, N·s/m], at the pads at
            a 45 mm opening (the servo drives the RG2's one crank: `gripper.crank_gain`); the
            servo pushes with at most the commanded force
            (`hrc_drake.cell.station.gripper.FingerServo`), and with all of it once a finger
            stalls `force / kp` short of its target. The fingers are commanded 1 mm each past the
            part (`motion.options.grip_squeeze`, 2 mm), of which the pads' give into the part
            and the linkage's couplers take some (0.3 mm each at 20 N on an oval flange): 60000
            squeezes it with 30 N of a 30 N command, 33 N of 40.
        grip_tolerance: m; a measured opening farther than this from the width of the part the
            gripper should hold means it holds nothing (or something else).
    """

    initial_opening: float = 0.088
    grip_force: float = 20.0
    kp: float = 60000.0
    kd: float = 40.0
    grip_tolerance: float = 0.004


@dataclass
class StationConfig:
    """What the simulated station holds beyond the assembly's models.

    Attributes:
        robot: add the UR3 and the gripper (False: the workpieces only, for fast cell tests).
        initial_placements: part instance -> a task token (`F1`, `S23`, `F02`) or `tray`; parts
            not named start in the tray.
        ur3, rg2: see their types. The station's cameras are Drake's own `CameraConfig`s, in
            the scenario's `cameras` (`DRAKE_SECTIONS`).
    """

    robot: bool = True
    initial_placements: dict[str, str] = field(default_factory=dict)
    ur3: ArmConfig = field(default_factory=ArmConfig)
    rg2: GripperConfig = field(default_factory=GripperConfig)


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


# The scenario's sections that are Drake's own config types, read by Drake's `yaml_load_typed`
# in the cell layer (`hrc_drake.cell.scenario.CellConfigs`: `MultibodyPlantConfig`,
# `SceneGraphConfig`, `SimulatorConfig`, `CameraConfig`s, `DrakeLcmParams` by bus). This layer
# is Drake-free: it reads only the rest, and keeps the text of these as given (`DrakeSection`).
DRAKE_SECTIONS = ("plant_config", "scene_graph_config", "simulator_config", "cameras", "lcm_buses")


@dataclass(frozen=True)
class DrakeSection:
    """One Drake section (`key`, one of `DRAKE_SECTIONS`) as one source gave it, as YAML flow
    text `{key: ...}`: the scenario file, or one `--scenario-text`. The cell layers them in
    order, as `hardware_sim` layers its `--scenario_text` on the file."""

    source: str
    key: str
    text: str


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
    run: RunConfig = field(default_factory=RunConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    station: StationConfig = field(default_factory=StationConfig)
    drivers: DriversConfig = field(default_factory=DriversConfig)
    # `ideal`, `realistic`, or a mapping (`hrc_drake.scenario.sensors`); the mapping first, as
    # Drake's loader reads an untagged value as the first member that fits.
    sensors: SensorsConfig | str = Preset.IDEAL.value
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    faults: list[FaultConfig] = field(default_factory=list)
    # The Drake sections as given, in order (filled by the loader, never a YAML key).
    drake: list[DrakeSection] = field(default_factory=list, metadata={"yaml": False})

    @property
    def assembly_path(self) -> Path:
        """The assembly spec file: `assembly` as a path, or a name under models/assemblies/
        (`assembly_file`, as `--assembly` resolves it)."""
        return assembly_file(self.assembly)

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


__all__ = [
    "DRAKE_SECTIONS",
    "TEXT_SOURCE",
    "ArmConfig",
    "BodyConfig",
    "DeciderConfig",
    "DelayConfig",
    "Deviation",
    "DrakeSection",
    "DriversConfig",
    "Expected",
    "GripperConfig",
    "InteractionConfig",
    "MotionConfig",
    "OperatorConfig",
    "RunConfig",
    "SafetyConfig",
    "Scenario",
    "ScenarioError",
    "SensorsConfig",
    "StationConfig",
    "assembly_file",
    "known_assemblies",
]
