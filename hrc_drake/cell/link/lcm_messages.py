"""The cell station's ports as LCM messages: the types, and the one conversion of each port value
to its message and back (which channel carries which: `hrc_drake.cell.link.channels`).

The UR3 uses Drake's own types: `lcmt_panda_command` carries joint positions *and* velocities
with a control-mode word (Drake's `lcmt_iiwa_command` has positions and torques only), and
`lcmt_panda_status` mirrors what UR's RTDE interface reports (actual_q, actual_qd, target_q,
target_qd, ...). Everything else is ours, because Drake's types do not fit: `lcmt_schunk_wsg_*`
count millimetres (a round trip m -> mm -> m is not exact in binary floating point, which the
lockstep co-simulation's equality needs) and carry no "grip detected" flag, and nothing in Drake
carries the configuration, the tracked body or the operator's messages.

Our types are written in LCM's own syntax (`DEFINITIONS`, also printed in `docs/hardware.md`) and
turned into Python classes by `LcmStruct` (`hrc_drake.cell.link.lcm_struct`) at import time: no
code generator. Their encoding and their fingerprint are those lcm-gen gives the same
definitions (the hash is checked against every Drake type in the tests), so a driver in C++ or
Java built with lcm-gen from `lcm_definitions()` talks to them unchanged. A message of another
type or definition fails to decode with `LcmDecodeError`, naming both fingerprints.
"""

from __future__ import annotations

import json
import math

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status

from hrc_drake.cell.link.lcm_struct import LcmDecodeError, parse_definitions
from hrc_drake.cell.ports import (
    BodySpheres,
    CellConfiguration,
    PartPlacement,
    PartStatus,
    SafetyMode,
)
from hrc_drake.cell.station.contacts import Owner
from hrc_drake.hri.messages import Indication, Prompt, PromptKind
from hrc_drake.robot_names import UR3_JOINTS

N_JOINTS = len(UR3_JOINTS)

DEFINITIONS = """
// The RG2's target: the opening between the finger insides, and the force to grip with.
struct lcmt_rg2_command {
    int64_t utime;          // the station time it applies from [us]
    double opening;         // [m], 0 to 0.110
    double force;           // [N], 3 to 40
}

// The load the UR3's tool meets: the force/torque sensor in a UR e-Series's tool flange
// (RTDE's actual_TCP_force), in the arm's base frame, signed as the tool meets it.
struct lcmt_ur3_tcp_force {
    int64_t utime;          // the station time of the measurement [us]
    double force[3];        // [N]
    double torque[3];       // about the tcp [N m]
}

// What the RG2 measures.
struct lcmt_rg2_status {
    int64_t utime;          // the station time of the measurement [us]
    double opening;         // between the finger insides [m]
    double opening_rate;    // [m/s]
    boolean grip_detected;  // the fingers stopped on an object before the target opening
}

// What the operator's interface shows (hrc_drake.hri.messages.Prompt).
struct lcmt_hri_prompt {
    int64_t utime;
    int32_t step;           // decision steps count from 1
    string kind;            // "none", "choose" or "bolt"
    int32_t num_state;
    string state[num_state];  // the tasks done so far
    string proposal;        // the robot's proposal
    string part;            // the part instance moved ("" until known)
    string committed;       // the task the robot started on before the answer ("": it waits)
}

// The operator's latest indication (hrc_drake.hri.messages.Indication).
struct lcmt_hri_indication {
    int64_t utime;
    int32_t step;
    boolean has_task;       // false: no task indicated yet (task is "")
    string task;
    boolean bolted;
    double time;            // when it was given [s, station clock]
}

// One part's placement (hrc_drake.cell.ports.PartPlacement).
struct lcmt_part_placement {
    string instance;        // the part's model instance, e.g. "oval_flange_1"
    string status;          // "seated", "held", "misplaced", "tray" or "transit"
    int32_t num_seats;
    string seats[num_seats];  // seat frames it sits in, e.g. "slot_1"
    int32_t num_slots;
    int32_t slots[num_slots]; // the plate's slots under it
    string host;            // model instance of the host part ("" for none)
    string token;           // task token, e.g. "F3" ("" unless seated in place)
    boolean has_pose;       // false: no pose measured (pose is all zeros)
    double pose[7];         // the part's world pose: x, y, z [m], then the unit quaternion
                            // w, x, y, z (whatever the status: seated, held, on the table...)
}

// The configuration sensor: which part sits where, and where each part lies (a camera, or the
// operator's confirmation with no poses, on a real cell).
struct lcmt_cell_configuration {
    int64_t utime;
    int32_t num_parts;
    lcmt_part_placement placements[num_parts];  // sorted by instance
    boolean has_obstacle;   // a temporary obstacle is seen in the work
    double obstacle[7];     // its world pose, as a part's (all zeros without one)
}

// The tracked operator body as world-frame spheres (hrc_drake.cell.ports.BodySpheres).
struct lcmt_operator_body {
    int64_t utime;
    int32_t num_spheres;
    double centres[num_spheres][3];     // [m]
    double radii[num_spheres];          // [m]
    double velocities[num_spheres][3];  // [m/s]
    int32_t num_groups;
    int32_t groups[num_groups][2];      // [start, end) of each body part's spheres
}

// Simulation only: the touching pairs of collision geometries (a run's collision watch).
struct lcmt_contacts {
    int64_t utime;
    int32_t num_contacts;
    string pairs[num_contacts][4];  // model, body, model, body of each touching pair
}

// The co-simulation session: "hello" (both, before the first step), "end" (controller),
// "report" and "error" (station).
struct lcmt_station_session {
    int64_t utime;
    string kind;
    string text;            // JSON for "hello" (the scenario's identity) and "report", the
                            // message for "error"
}
"""

_TYPES = parse_definitions(DEFINITIONS, __name__)
lcmt_rg2_command = _TYPES["lcmt_rg2_command"]
lcmt_rg2_status = _TYPES["lcmt_rg2_status"]
lcmt_ur3_tcp_force = _TYPES["lcmt_ur3_tcp_force"]
lcmt_hri_prompt = _TYPES["lcmt_hri_prompt"]
lcmt_hri_indication = _TYPES["lcmt_hri_indication"]
lcmt_part_placement = _TYPES["lcmt_part_placement"]
lcmt_cell_configuration = _TYPES["lcmt_cell_configuration"]
lcmt_operator_body = _TYPES["lcmt_operator_body"]
lcmt_contacts = _TYPES["lcmt_contacts"]
lcmt_station_session = _TYPES["lcmt_station_session"]


def lcm_definitions() -> str:
    """Our message types in LCM syntax, with their comments (the input of lcm-gen)."""
    return DEFINITIONS.strip() + "\n"


# --- the station's ports as messages -------------------------------------------------------
def utime(t: float) -> int:
    """A time stamp [us] of station time `t` [s]."""
    return round(t * 1e6)


def _count(values, n: int, what: str) -> list[float]:
    values = [float(x) for x in values]
    if len(values) != n:
        raise LcmDecodeError(f"{what}: {len(values)} values where {n} are expected")
    return values


def ur3_command(stamp: int, position, velocity) -> lcmt_panda_command:
    """`ur3.position` and `ur3.velocity` as a joint position and velocity command."""
    message = lcmt_panda_command()
    message.utime = stamp
    message.num_joint_position = message.num_joint_velocity = N_JOINTS
    message.joint_position = _count(position, N_JOINTS, "ur3.position")
    message.joint_velocity = _count(velocity, N_JOINTS, "ur3.velocity")
    message.num_joint_torque, message.joint_torque = 0, []
    message.control_mode_expected = (
        lcmt_panda_status.CONTROL_MODE_POSITION | lcmt_panda_status.CONTROL_MODE_VELOCITY
    )
    return message


def ur3_command_values(message: lcmt_panda_command) -> tuple[np.ndarray, np.ndarray]:
    """(`ur3.position`, `ur3.velocity`) of a UR3 command."""
    position = _count(message.joint_position, N_JOINTS, "UR3 command positions")
    velocity = _count(message.joint_velocity, N_JOINTS, "UR3 command velocities")
    return np.array(position), np.array(velocity)


_UR3_STATUS_NOT_SIMULATED = (
    "joint_position_desired",
    "joint_velocity_desired",
    "joint_acceleration_desired",
    "joint_torque",
    "joint_torque_desired",
    "joint_torque_external",
)


# The robot's safety mode as the Panda status's robot mode: a protective stop is `kReflex` (the
# arm stopped by its safety system), a safeguard stop `kUserStopped` (stopped by an outside
# safeguard), the reduced mode `kOther` (the message has none of its own), normal `kMove`.
_ROBOT_MODE = {
    SafetyMode.NORMAL: lcmt_panda_status.kMove,
    SafetyMode.REDUCED: lcmt_panda_status.kOther,
    SafetyMode.PROTECTIVE_STOP: lcmt_panda_status.kReflex,
    SafetyMode.SAFEGUARD_STOP: lcmt_panda_status.kUserStopped,
}
_SAFETY_MODE = {robot: safety for safety, robot in _ROBOT_MODE.items()}


def ur3_status(stamp: int, state, stop, mode) -> lcmt_panda_status:
    """`ur3.state_estimated` (positions, then velocities), `safety.stop` and `safety.mode` as a
    UR3 status: the safety mode is the robot mode (`_ROBOT_MODE`), which also says the stop.
    The simulated station measures no torques and reports no targets: those members are NaN
    (a real driver fills them from RTDE, see docs/hardware.md)."""
    state = _count(state, 2 * N_JOINTS, "ur3.state_estimated")
    (stopped,) = _count(stop, 1, "safety.stop")
    (code,) = _count(mode, 1, "safety.mode")
    try:
        safety = SafetyMode(round(code))
    except ValueError as err:
        raise ValueError(
            f"safety.mode {code} is not a safety mode; use one of "
            f"{', '.join(f'{m.value} ({m.name.lower()})' for m in SafetyMode)}"
        ) from err
    if (stopped > 0.5) != safety.stopped:
        raise ValueError(f"safety.stop {stopped} disagrees with safety.mode {safety.name}")
    unknown = [math.nan] * N_JOINTS
    message = lcmt_panda_status()
    message.utime = message.robot_utime = stamp
    message.num_joints = N_JOINTS
    message.joint_position, message.joint_velocity = state[:N_JOINTS], state[N_JOINTS:]
    for name in _UR3_STATUS_NOT_SIMULATED:
        setattr(message, name, unknown)
    message.control_command_success_rate = math.nan
    message.robot_mode = _ROBOT_MODE[safety]
    message.control_mode = (
        lcmt_panda_status.CONTROL_MODE_POSITION | lcmt_panda_status.CONTROL_MODE_VELOCITY
    )
    return message


def ur3_status_values(message: lcmt_panda_status) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(`ur3.state_estimated`, `safety.stop`, `safety.mode`) of a UR3 status (a robot mode
    that is none of `_ROBOT_MODE`'s reads as normal)."""
    position = _count(message.joint_position, N_JOINTS, "UR3 status positions")
    velocity = _count(message.joint_velocity, N_JOINTS, "UR3 status velocities")
    safety = _SAFETY_MODE.get(message.robot_mode, SafetyMode.NORMAL)
    return (
        np.array(position + velocity),
        np.array([1.0 if safety.stopped else 0.0]),
        np.array([float(safety)]),
    )


def tcp_force_message(stamp: int, wrench) -> lcmt_ur3_tcp_force:
    """`ur3.tcp_force` (force, then moment) as a UR3 wrist load."""
    values = _count(wrench, 6, "ur3.tcp_force")
    return lcmt_ur3_tcp_force(utime=stamp, force=values[:3], torque=values[3:])


def tcp_force_value(message) -> tuple[np.ndarray]:
    """(`ur3.tcp_force`,) of a UR3 wrist load."""
    force = _count(message.force, 3, "UR3 wrist force")
    torque = _count(message.torque, 3, "UR3 wrist torque")
    return (np.array(force + torque),)


def rg2_command(stamp: int, opening, force) -> lcmt_rg2_command:
    """`rg2.opening` and `rg2.force` as an RG2 target."""
    (value,) = _count(opening, 1, "rg2.opening")
    (newtons,) = _count(force, 1, "rg2.force")
    return lcmt_rg2_command(utime=stamp, opening=value, force=newtons)


def rg2_command_values(message) -> tuple[np.ndarray, np.ndarray]:
    """(`rg2.opening`, `rg2.force`) of an RG2 command."""
    return np.array([message.opening]), np.array([message.force])


def rg2_status(stamp: int, measured, grip_detected) -> lcmt_rg2_status:
    """`rg2.state_measured` (opening, rate) and `rg2.grip_detected` as an RG2 status."""
    opening, rate = _count(measured, 2, "rg2.state_measured")
    (grip,) = _count(grip_detected, 1, "rg2.grip_detected")
    return lcmt_rg2_status(
        utime=stamp, opening=opening, opening_rate=rate, grip_detected=grip > 0.5
    )


def rg2_status_values(message) -> tuple[np.ndarray, np.ndarray]:
    """(`rg2.state_measured`, `rg2.grip_detected`) of an RG2 status."""
    grip = 1.0 if message.grip_detected else 0.0
    return np.array([message.opening, message.opening_rate]), np.array([grip])


def prompt_message(stamp: int, prompt: Prompt):
    """`hri.prompt` as a message."""
    return lcmt_hri_prompt(
        utime=stamp,
        step=prompt.step,
        kind=str(prompt.kind),
        num_state=len(prompt.state),
        state=list(prompt.state),
        proposal=prompt.proposal,
        part=prompt.part,
        committed=prompt.committed,
    )


def prompt_value(message) -> tuple[Prompt]:
    """(`hri.prompt`,) of a prompt message."""
    try:
        kind = PromptKind(message.kind)
    except ValueError:
        raise LcmDecodeError(f"a prompt of unknown kind {message.kind!r}") from None
    state = tuple(message.state)
    return (Prompt(message.step, kind, state, message.proposal, message.part, message.committed),)


def indication_message(stamp: int, indication: Indication):
    """`hri.indication` as a message."""
    return lcmt_hri_indication(
        utime=stamp,
        step=indication.step,
        has_task=indication.task is not None,
        task=indication.task or "",
        bolted=indication.bolted,
        time=indication.time,
    )


def indication_value(message) -> tuple[Indication]:
    """(`hri.indication`,) of an indication message."""
    task = message.task if message.has_task else None
    return (Indication(message.step, task, message.bolted, message.time),)


def configuration_message(stamp: int, configuration: CellConfiguration):
    """`configuration` as a message ("" stands for a missing host or token; `has_pose` false
    and seven zeros for a placement without a pose)."""
    for name, p in configuration.placements:
        if len(p.pose) not in (0, 7):
            raise ValueError(
                f"configuration: {name} has a pose of {len(p.pose)} values; a pose is 7 (x, y, "
                "z, qw, qx, qy, qz) or none"
            )
    placements = [
        lcmt_part_placement(
            instance=name,
            status=p.status.value,
            num_seats=len(p.seats),
            seats=list(p.seats),
            num_slots=len(p.slots),
            slots=list(p.slots),
            host=p.host or "",
            token=p.token or "",
            has_pose=bool(p.pose),
            pose=list(p.pose) if p.pose else [0.0] * 7,
        )
        for name, p in configuration.placements
    ]
    obstacle = configuration.obstacle
    if len(obstacle) not in (0, 7):
        raise ValueError(f"configuration: an obstacle pose of {len(obstacle)} values; give 7")
    return lcmt_cell_configuration(
        utime=stamp,
        num_parts=len(placements),
        placements=placements,
        has_obstacle=bool(obstacle),
        obstacle=list(obstacle) if obstacle else [0.0] * 7,
    )


def configuration_value(message) -> tuple[CellConfiguration]:
    """(`configuration`,) of a configuration message."""
    try:
        placements = tuple(
            (
                p.instance,
                PartPlacement(
                    PartStatus(p.status),
                    tuple(p.seats),
                    tuple(p.slots),
                    p.host or None,
                    p.token or None,
                    tuple(float(x) for x in p.pose) if p.has_pose else (),
                ),
            )
            for p in message.placements
        )
    except ValueError as err:
        raise LcmDecodeError(f"a configuration message: {err}") from None
    obstacle = tuple(float(x) for x in message.obstacle) if message.has_obstacle else ()
    return (CellConfiguration(placements, obstacle),)


def body_message(stamp: int, body: BodySpheres):
    """`operator.body` as a message."""
    n = len(body.radii)
    return lcmt_operator_body(
        utime=stamp,
        num_spheres=n,
        centres=np.asarray(body.centres, dtype=float).reshape(n, 3).tolist(),
        radii=np.asarray(body.radii, dtype=float).tolist(),
        velocities=np.asarray(body.velocities, dtype=float).reshape(n, 3).tolist(),
        num_groups=len(body.groups),
        groups=[[int(start), int(end)] for start, end in body.groups],
    )


def body_value(message) -> tuple[BodySpheres]:
    """(`operator.body`,) of a body message."""
    n = message.num_spheres
    return (
        BodySpheres(
            np.array(message.centres, dtype=float).reshape(n, 3),
            np.array(message.radii, dtype=float).reshape(n),
            np.array(message.velocities, dtype=float).reshape(n, 3),
            tuple((start, end) for start, end in message.groups),
        ),
    )


Contacts = tuple[tuple[Owner, Owner], ...]
"""Simulation only: the touching pairs of collision geometries, by owner (model, body)."""


def contacts_message(stamp: int, contacts: Contacts):
    """The touching pairs (simulation only) as a message."""
    pairs = [[a.model, a.body, b.model, b.body] for a, b in contacts]
    return lcmt_contacts(utime=stamp, num_contacts=len(pairs), pairs=pairs)


def contacts_value(message) -> tuple[Contacts]:
    """(touching pairs,) of a contacts message."""
    return (tuple((Owner(ma, ba), Owner(mb, bb)) for ma, ba, mb, bb in message.pairs),)


def session_message(stamp: int, kind: str, payload: str | dict = "") -> object:
    """A session message; a dict payload is sent as JSON."""
    text = payload if isinstance(payload, str) else json.dumps(payload)
    return lcmt_station_session(utime=stamp, kind=kind, text=text)
