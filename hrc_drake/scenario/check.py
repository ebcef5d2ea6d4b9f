"""A scenario checked before anything is built: values finite, in range and known, the
faults and the operator consistent with the run; one-line `ScenarioError`s naming the key and
where the value came from (a file, or `--scenario-text`)."""

import dataclasses
import math

import numpy as np

from hrc_drake.hri.faults import FaultError, SafetySensorSilent, check_faults
from hrc_drake.robot_names import UR3_JOINTS, UR3_VELOCITY_LIMITS
from hrc_drake.scenario.safety import (
    HumanSpeed,
    RobotLimitsConfig,
    SafeguardReset,
    SafetyConfig,
    SafetyFunctionConfig,
    SafetySensorConfig,
    Separation,
    Timing,
)
from hrc_drake.scenario.schema import (
    TEXT_SOURCE,
    Activity,
    Behaviour,
    DeciderConfig,
    InteractionConfig,
    Scenario,
    ScenarioError,
    assembly_file,
)
from hrc_drake.scenario.sensors import sensor_models
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.tasks.interaction import (
    INTERFACES,
    MODES,
    IndicationDelay,
    InteractionError,
)
from hrc_drake.typed_yaml import Tagged

# The fastest the UR3 can move the RG2's TCP [m/s]: every joint at its published speed limit
# (UR3/CB3 user manual v3.13 via ros-industrial `ur_description/config/ur3/joint_limits.yaml`:
# 180 deg/s base, shoulder, elbow; 360 deg/s wrists; `robot_names.UR3_VELOCITY_LIMITS`), through
# UR's published DH parameters, with the TCP 0.216 m past the flange (OnRobot's RG2 URDF),
# maximised over the configurations: 7.49 m/s (4.46 m/s at the flange). Universal Robots
# publishes no TCP maximum for the arm itself (its safety system's TCP limit is a setting), so a
# `tcp_speed_limit` above this limits nothing the joints do not already: it is a typo (50 for
# 0.5) or a unit slip (mm/s for m/s). tests/test_careless_inputs.py recomputes it.
UR3_TCP_SPEED_MAX = 7.5
# ISO 10218-1's reduced speed [m/s], the default TCP limit: named in the errors as the fix.
REDUCED_SPEED = 0.25


def check_finite(value, key: str, fail) -> None:
    """Refuse NaN and infinity anywhere in a scenario (YAML's `.nan`, `.inf`), `fail(key,
    problem)` naming the first: every number of a scenario is a quantity of the cell, and a NaN
    passes every `<` and `>` check below, to fail later in Drake (a NaN hold time is an
    assertion in the planning worker, an infinite one a run that never ends). Walks dataclasses,
    lists, mappings and tagged YAML nodes (the Drake sections as read, `!Rpy {deg: [...]}`)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise fail(key, f"{value} is not a number the cell can use; give a finite number")
    elif isinstance(value, Tagged):
        check_finite(value.value, key, fail)
    elif dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            check_finite(getattr(value, f.name), f"{key}.{f.name}" if key else f.name, fail)
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            check_finite(item, f"{key}[{i}]", fail)
    elif isinstance(value, dict):
        for k, item in value.items():
            check_finite(item, f"{key}.{k}", fail)


def _check_limits(scenario, fail) -> None:
    """The signs and ranges of the numbers no other check covers: each of these, out of range,
    fails only once the cell is built or the run has started (or never, silently)."""
    if scenario.run.max_steps < 1:
        raise fail("run.max_steps", f"a run takes at least 1 step, got {scenario.run.max_steps}")
    for key in ("robot_uncertainty", "slow_band", "moving_speed"):
        if getattr(scenario.safety, key) < 0:
            raise fail(f"safety.{key}", f"must be >= 0, got {getattr(scenario.safety, key)}")
    fastest = max(UR3_VELOCITY_LIMITS)
    if scenario.safety.moving_speed >= fastest:
        # Above the fastest joint's published limit no joint would ever count as moving.
        raise fail(
            "safety.moving_speed",
            f"{scenario.safety.moving_speed} rad/s is beyond the UR3's fastest joint "
            f"({fastest:.2f} rad/s, 360 deg/s), so no joint would ever count as moving; give "
            f"rad/s in [0, {fastest:.2f}) (0.01)",
        )
    arm, rg2 = scenario.station.ur3, scenario.station.rg2
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


def check_scenario(scenario: Scenario, source: str) -> Scenario:
    """Value checks the types cannot express; ScenarioError naming the key. The sections are
    checked in the order of the file (the first problem is the one named)."""

    where = source if source == TEXT_SOURCE else f"scenario {source}"

    def fail(key: str, problem: str) -> ScenarioError:
        return ScenarioError(f"{where}: {key}: {problem}")

    check_finite(scenario, "", fail)
    try:  # a name not under models/assemblies/: one line, with the known ones
        assembly_file(scenario.assembly)
    except SpecError as err:
        raise fail("assembly", str(err).removeprefix("assembly ")) from None
    _check_limits(scenario, fail)
    _check_operator(scenario, fail)
    _check_decider(scenario.decider, fail)
    _check_motion(scenario, fail)
    _check_run(scenario, fail)
    _check_safety_body_and_station(scenario, fail)
    if scenario.cell is not None:
        try:
            scenario.cell.check("cell")
        except ValueError as err:
            raise ScenarioError(f"{where}: {err}") from err
    _check_body(scenario, fail)
    _check_separation(scenario.safety, fail)
    _check_safety_sensor(scenario.safety.sensor, fail, scenario.faults)
    _check_robot_limits(scenario.safety.limits, fail)
    _check_interaction(scenario.interaction, fail)
    try:
        scenario.drivers.check("drivers")
        sensor_models(scenario.sensors, "sensors")
    except ValueError as err:
        raise ScenarioError(f"{where}: {err}") from err
    try:
        check_faults(scenario.faults, source, UR3_JOINTS)
    except FaultError as err:
        raise ScenarioError(str(err)) from err
    return scenario


def _check_operator(scenario: Scenario, fail) -> None:
    """The operator's probabilities, scripted deviations and delay seed."""
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


def _check_motion(scenario: Scenario, fail) -> None:
    """Motion times and speeds."""
    for key in ("hold_time", "approach_distance"):
        if getattr(scenario.motion, key) < 0:
            raise fail(f"motion.{key}", "must be >= 0")
    _check_tcp_speed(scenario.motion.tcp_speed_limit, "motion.tcp_speed_limit", fail)
    # The plant's step and contact material are Drake's own configs, checked where Drake reads
    # them (`hrc_drake.cell.scenario.cell_configs`).


def _check_tcp_speed(speed: float, key: str, fail, zero: str = "") -> None:
    """A TCP speed [m/s] the UR3 can reach: in (0, UR3_TCP_SPEED_MAX], or [0, ...] when `zero`
    says what 0 means."""
    low = "[0" if zero else "(0"
    if (speed < 0 if zero else speed <= 0) or speed > UR3_TCP_SPEED_MAX:
        beyond = speed > UR3_TCP_SPEED_MAX
        why = (
            f"beyond the UR3 (its joints' published speed limits move the TCP at most "
            f"{UR3_TCP_SPEED_MAX} m/s)"
            if beyond
            else "not a speed the robot can move at"
        )
        raise fail(
            key,
            f"{speed} m/s is {why}; give a speed in {low}, {UR3_TCP_SPEED_MAX}] m/s "
            f"({REDUCED_SPEED}: ISO 10218-1's reduced speed{zero})",
        )


def _check_run(scenario: Scenario, fail) -> None:
    """The run's periods, timeouts and retries."""
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
    guard = scenario.run.place_guard
    if not (math.isfinite(guard) and guard >= 0):
        raise fail("run.place_guard", f"give newtons >= 0 (0: no guard), got {guard}")


def _check_safety_body_and_station(scenario: Scenario, fail) -> None:
    """The separation formula's terms, the body's coordinates and the gripper's force."""
    _check_tcp_speed(
        scenario.safety.contact_speed, "safety.contact_speed", fail, "; 0: separation alone"
    )
    for key in (
        "reaction_time",
        "intrusion",
        "human_uncertainty",
    ):
        if getattr(scenario.safety, key) < 0:
            raise fail(f"safety.{key}", "must be >= 0")
    for key in ("stance", "rest_hand", "reach_offset"):
        want = 2 if key == "stance" else 3
        if len(getattr(scenario.body, key)) != want:
            raise fail(f"body.{key}", f"give {want} coordinates in metres")
    if not 3.0 <= scenario.station.rg2.grip_force <= 40.0:
        raise fail("station.rg2.grip_force", "the RG2 grips with 3 to 40 N")


def _check_decider(decider: DeciderConfig, fail) -> None:
    """A known decider name (or none)."""
    from hrc_drake.tasks.deciders import DECIDERS

    if decider.name and decider.name not in DECIDERS:
        known = ", ".join(DECIDERS)
        raise fail("decider.name", f"unknown decider {decider.name!r}; use one of {known}")


SEPARATION_MODES = tuple(m.value for m in Separation)
TIMINGS = tuple(t.value for t in Timing)
ACTIVITIES = tuple(a.value for a in Activity)
BEHAVIOURS = tuple(b.value for b in Behaviour)


def _check_separation(safety: SafetyConfig, fail) -> None:
    """The separation mode and the forecast's bounds."""
    if safety.separation not in SEPARATION_MODES:
        raise fail(
            "safety.separation",
            f"unknown mode {safety.separation!r}; use {' or '.join(SEPARATION_MODES)}",
        )
    if safety.timing not in TIMINGS:
        raise fail("safety.timing", f"unknown timing {safety.timing!r}; use {' or '.join(TIMINGS)}")
    if safety.departure <= 0:
        raise fail("safety.departure", f"give a distance > 0 m, got {safety.departure}")
    if safety.max_wait < 0:
        raise fail("safety.max_wait", f"give seconds >= 0, got {safety.max_wait}")
    if not 0.0 <= safety.forecast_spread <= 1.0:
        raise fail(
            "safety.forecast_spread", f"give a fraction in [0, 1], got {safety.forecast_spread}"
        )
    if safety.human_speed not in HUMAN_SPEEDS:
        raise fail(
            "safety.human_speed",
            f"unknown speed {safety.human_speed!r}; use {' or '.join(HUMAN_SPEEDS)} (the "
            "constant speeds are ISO 13855's)",
        )
    if safety.hand_acceleration <= 0:
        raise fail(
            "safety.hand_acceleration",
            f"give an acceleration > 0 m/s² (30 bounds the simulated hands), got "
            f"{safety.hand_acceleration}",
        )
    _check_safety_function(safety.function, fail)


HUMAN_SPEEDS = tuple(m.value for m in HumanSpeed)


def _check_safety_function(function: SafetyFunctionConfig, fail) -> None:
    """The station's safety function: distances it can keep."""
    resets = tuple(r.value for r in SafeguardReset)
    if function.safeguard_reset not in resets:
        raise fail(
            "safety.function.safeguard_reset",
            f"give {' or '.join(resets)}, got {function.safeguard_reset!r}",
        )
    for key in ("resume_clearance", "reduced_band"):
        if getattr(function, key) < 0:
            raise fail(f"safety.function.{key}", f"give metres >= 0, got {getattr(function, key)}")


def _check_robot_limits(limits: RobotLimitsConfig, fail) -> None:
    """The UR's limit sets: speeds it can keep, the reduced set no looser than the normal."""
    keys = ("tool_speed", "elbow_speed", "momentum")
    for name in ("normal", "reduced"):
        for key in keys:
            value = getattr(getattr(limits, name), key)
            if not value > 0:
                raise fail(f"safety.limits.{name}.{key}", f"give a limit > 0, got {value}")
    for key in keys:
        normal, reduced = getattr(limits.normal, key), getattr(limits.reduced, key)
        if reduced > normal:
            raise fail(
                f"safety.limits.reduced.{key}",
                f"{reduced} is above the normal set's {normal}: a reduced limit is no looser",
            )
    for key in ("tolerance", "detection_time", "transition"):
        if getattr(limits, key) < 0:
            raise fail(f"safety.limits.{key}", f"give a value >= 0, got {getattr(limits, key)}")
    plane = limits.reduced_plane
    if plane is not None:
        for key in ("point", "normal"):
            value = getattr(plane, key)
            if len(value) != 3 or not all(math.isfinite(x) for x in value):
                raise fail(f"safety.limits.reduced_plane.{key}", f"give [x, y, z], got {value}")
        if not np.linalg.norm(plane.normal) > 0:
            raise fail("safety.limits.reduced_plane.normal", "give a nonzero normal")


def _check_safety_sensor(sensor: SafetySensorConfig, fail, faults=()) -> None:
    """The safety sensor: units that see something, a monitored space with voxels in it; a
    silent-unit fault names one of its units."""
    for k, fault in enumerate(faults):
        if not isinstance(fault, SafetySensorSilent):
            continue
        if not sensor.enabled:
            raise fail(f"faults[{k}]", "!SafetySensorSilent needs `safety.sensor.enabled: true`")
        names = [u.name for u in sensor.units]
        if fault.unit and fault.unit not in names:
            raise fail(f"faults[{k}].unit", f"no unit {fault.unit!r}; the units are {names}")
    if not sensor.enabled:
        return
    if not sensor.units:
        raise fail("safety.sensor.units", "give at least one unit (or `enabled: false`)")
    names = [u.name for u in sensor.units]
    if len(set(names)) != len(names):
        raise fail("safety.sensor.units", f"give each unit its own name, got {names}")
    for k, unit in enumerate(sensor.units):
        key = f"safety.sensor.units[{k}]"
        for name in ("position", "target"):
            if len(getattr(unit, name)) != 3:
                raise fail(f"{key}.{name}", "give [x, y, z] in metres")
        if np.allclose(unit.position, unit.target):
            raise fail(f"{key}.target", "give a point the unit looks at, away from its position")
        if len(unit.field_of_view) != 2 or not all(0 < a < 180 for a in unit.field_of_view):
            raise fail(f"{key}.field_of_view", "give [wide, narrow] degrees, each in (0, 180)")
        for name in ("reach", "frame_rate", "response_time", "detection"):
            if getattr(unit, name) <= 0:
                raise fail(f"{key}.{name}", f"give a value > 0, got {getattr(unit, name)}")
        if unit.response_time < 1.0 / unit.frame_rate:
            raise fail(
                f"{key}.response_time",
                f"give at least one frame period ({1.0 / unit.frame_rate:.3f} s at "
                f"{unit.frame_rate} Hz), got {unit.response_time}",
            )
    space = np.asarray(sensor.space, dtype=float)
    if space.shape != (2, 3) or np.any(space[1] <= space[0]):
        raise fail("safety.sensor.space", "give [[x, y, z], [x, y, z]], lower then upper corner")
    if not 0 < sensor.voxel <= 0.2:
        raise fail("safety.sensor.voxel", f"give an edge in (0, 0.2] m, got {sensor.voxel}")
    if sensor.margin < 0:
        raise fail("safety.sensor.margin", f"give metres >= 0, got {sensor.margin}")
    if len({u.frame_rate for u in sensor.units}) > 1:
        raise fail("safety.sensor.units", "give every unit one frame rate (they are synchronised)")
    if sensor.performance_level not in ("a", "b", "c", "d", "e"):
        raise fail("safety.sensor.performance_level", "give one of a, b, c, d, e")


def _check_body(scenario: Scenario, fail) -> None:
    """The operator's body: its values, and bins its hand reaches (with either hand, when
    persons vary)."""
    body = scenario.body
    if not 0 < body.hand_speed <= 2.0:
        raise fail("body.hand_speed", "give a speed in (0, 2] m/s (1.6 m/s: ISO 13855)")
    if body.activity not in ACTIVITIES:
        raise fail("body.activity", f"unknown activity {body.activity!r}; use one of {ACTIVITIES}")
    if body.behaviour not in BEHAVIOURS:
        known = " or ".join(BEHAVIOURS)
        raise fail("body.behaviour", f"unknown behaviour {body.behaviour!r}; use {known}")
    if body.behaviour != Behaviour.MODELLED and body.activity != Activity.DESK:
        raise fail(
            "body.behaviour",
            f"{body.behaviour!r} is a way of doing the desk activity; "
            f"set body.activity: desk too, or leave behaviour {Behaviour.MODELLED.value!r}",
        )
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
    if body.activity != Activity.DESK or not body.enabled:
        return
    layout = scenario.cell
    if layout is None:
        from hrc_drake.layout import layout_from
        from hrc_drake.tasks.assembly import SpecError
        from hrc_drake.tasks.spec import load_spec

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


__all__ = ["ACTIVITIES", "BEHAVIOURS", "SEPARATION_MODES", "check_scenario"]
