"""The station's things in the robot's way (simulator only): the box of a `no-path` fault and
the debris of a `no-seat` fault with `obstacle: true` (`hrc_drake.obstacle_models`).

Each rides an x-y-z carriage servoed by the plant's PD actuators; the fault injector sets its
target. The box touches only the robot and what the robot carries: it is there to be in the
robot's way, not to move parts. The debris touches only the parts (it comes down into its
pocket from above, past the arm, and lies on the pocket's floor, in the plate or in a host
part). Where they go: over, or into the pocket of, the seat of the task the robot proposes, so
that the task the operator then confirms has no path until the box is taken away, or its part
lands on the debris.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PdControllerGains

from hrc_drake.cell.station.arm_servo import servo_actuators
from hrc_drake.cell.station.contacts import geometry_owners
from hrc_drake.cell_models import TABLE
from hrc_drake.hri.faults import NoPath, NoSeat
from hrc_drake.hri.messages import Prompt
from hrc_drake.motion.poses import CellFrames, part_pose
from hrc_drake.obstacle_models import DEBRIS, DEBRIS_SIZE, OBSTACLE, add_mounted_obstacle
from hrc_drake.robot_names import GRIPPER, UR3
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO
from hrc_drake.workpiece_sdf import PLATE, POCKET_DEPTH, SEAT_GAP, TRAY

# The carriage's servo: stiff enough that the box stands where it is put (it settles in about
# 0.1 s), critically damped for the carriage's 0.6 kg.
_KP = 4000.0  # N/m
_KD = 100.0  # N·s/m


def mounted_obstacles(faults) -> tuple[str, ...]:
    """The things a scenario's faults need on carriages: OBSTACLE (a no-path fault), DEBRIS (a
    no-seat fault with an obstacle)."""
    box = any(isinstance(f, NoPath) for f in faults)
    debris = any(isinstance(f, NoSeat) and f.obstacle for f in faults)
    return (OBSTACLE,) * box + (DEBRIS,) * debris


def mount_obstacle(plant: MultibodyPlant, name: str):
    """Add the box or the debris on its carriage (before Finalize): servoed, without weight (its
    servo holds it like a hand, or as stuck in the pocket); returns its model instance."""
    model = add_mounted_obstacle(plant, name)
    for actuator in servo_actuators(plant, model):
        actuator.set_controller_gains(PdControllerGains(p=_KP, d=_KD))
    plant.set_gravity_enabled(model, False)
    return model


def filter_obstacle_contacts(plant: MultibodyPlant, scene_graph, name: str) -> None:
    """What the box or debris does not touch (after Finalize): the box, anything but the robot;
    the debris, the plate, tray, table and the robot."""
    owners = geometry_owners(plant)
    if name == OBSTACLE:
        touches = {UR3, GRIPPER, name}
        passes = [g for g, owner in owners.items() if owner.model not in touches]
    else:
        names = {PLATE, TRAY, TABLE, UR3, GRIPPER}
        passes = [g for g, owner in owners.items() if owner.model in names]
    mine = [g for g, owner in owners.items() if owner.model == name]
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeBetween(GeometrySet(mine), GeometrySet(passes))
    )


class SeatPositions:
    """Where the robot's proposal of a prompt puts its part (or, for `undo`, takes it from),
    from the cell's frames and the task space."""

    def __init__(self, frames: CellFrames, space: StateSpace):
        self._frames = frames
        self._space = space

    def _token(self, prompt: Prompt) -> tuple[str, frozenset[str]]:
        state = tuple(prompt.state)
        configuration = self._space.configuration(self._space.index(state))
        if prompt.proposal == UNDO:
            return state[-1], configuration
        return prompt.proposal, configuration | {prompt.proposal}

    def __call__(self, prompt: Prompt) -> np.ndarray:
        """The seat's world position [m] (a seated part's underside centre), for a CHOOSE
        prompt."""
        token, configuration = self._token(prompt)
        return np.asarray(part_pose(self._frames, token, configuration).translation())

    def pocket(self, prompt: Prompt) -> np.ndarray:
        """The centre of the debris lying on the floor of the seat's (first) pocket [m]."""
        token, configuration = self._token(prompt)
        placement = self._frames.spec.placement(token)
        if placement.host is None:
            X_W_seat: RigidTransform = self._frames.seats[placement.slots[0]]
        else:
            X_W_seat = part_pose(self._frames, token, configuration)
        floor = X_W_seat @ np.array([0.0, 0.0, -(SEAT_GAP + POCKET_DEPTH)])
        return floor + np.array([0.0, 0.0, DEBRIS_SIZE[2] / 2])


__all__ = ["SeatPositions", "filter_obstacle_contacts", "mount_obstacle", "mounted_obstacles"]
