"""Things in the robot's way: the box of a `no-path` fault, the debris of a `no-seat` one.

The box is something someone sets down on the work, big enough for the cell to see. One fact,
two plants: the simulated station mounts it on three prismatic joints (x, y, z) whose servo the
fault injector commands, parked under the table top until the fault strikes, then set down
over the seat the robot is to reach, then taken away; the planning scene welds the same box to a
world frame whose pose each layout sets (parked far below the cell when the cell measures no
box). Only the robot (and what it carries) can touch the box: it passes through the table,
plate, tray and parts, which it is not there to move.

The debris is a nut dropped into a pocket: too small for the configuration sensor (it reads
parts and the box), it stops a part from seating. The station mounts it like the box; it
touches the parts and the robot, not the plate whose pocket it lies in.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Box, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    PrismaticJoint,
    RigidBody,
    SpatialInertia,
    UnitInertia,
)

OBSTACLE = "obstacle"
DEBRIS = "debris"
# An M6 nut lying flat (ISO 4032: 10 mm across flats, 5.2 mm high) stands taller than a
# pocket is deep; a flat washer-like bit of 3 mm is enough to hold a boss a seat's tolerance
# (1 mm) high. Our assumption.
DEBRIS_SIZE = (0.008, 0.008, 0.003)  # m
DEBRIS_MASS = 0.002  # kg
# A parts bin as big as a hand (our assumption): wider than a flange's pocket and taller than the
# pre-place height above it, so neither the place pose nor the straight way down is free.
OBSTACLE_SIZE = (0.10, 0.10, 0.12)  # m
OBSTACLE_MASS = 0.5  # kg

# The carriage links between the joints (light, not massless: SAP needs a mass matrix it can
# factor).
_CARRIAGE_MASS = 0.05  # kg
# Where the box waits out of the work: under the 40 mm table top, beside the robot.
OBSTACLE_PARK = (0.25, 0.0, -0.30)
# Where the debris waits: high above the work, so that it comes down into its pocket from above
# (from below it would pass through a host part under the pocket, which it must stop).
DEBRIS_PARK = (0.25, 0.0, 0.80)
# The cell sees a box whose bottom is above this height [m] (the table top is at 0): a parked
# box is not in the work.
OBSTACLE_SEEN_ABOVE = -0.05
# Where the planning scene parks its box when the cell measures none.
_FAR_BELOW = RigidTransform([0.0, 0.0, -10.0])
_COLOUR = np.array([0.95, 0.45, 0.1, 0.8])


def obstacle_pose_over(p_W_seat: np.ndarray) -> RigidTransform:
    """The box's pose set down over a part's seat (its body frame at the box's centre)."""
    x, y, z = (float(v) for v in p_W_seat)
    return RigidTransform([x, y, z + OBSTACLE_SIZE[2] / 2])


def _add_box_body(plant: MultibodyPlant, model, name: str = OBSTACLE) -> RigidBody:
    size, mass = (OBSTACLE_SIZE, OBSTACLE_MASS) if name == OBSTACLE else (DEBRIS_SIZE, DEBRIS_MASS)
    box = Box(*size)
    body = plant.AddRigidBody(name, model, SpatialInertia.SolidBoxWithMass(mass, *size))
    props = ProximityProperties()
    props.AddProperty("material", "coulomb_friction", CoulombFriction(0.5, 0.5))
    plant.RegisterCollisionGeometry(body, RigidTransform(), box, "box", props)
    plant.RegisterVisualGeometry(body, RigidTransform(), box, "box_visual", _COLOUR)
    return body


def add_mounted_obstacle(plant: MultibodyPlant, name: str = OBSTACLE):
    """The station's box (or, `name` DEBRIS, debris) on its x-y-z carriage (before Finalize),
    parked; returns its model instance (named `name`, as its body). Each joint (`<name>_x`,
    `_y`, `_z`) has an actuator for the plant's PD servo (set its gains)."""
    model = plant.AddModelInstance(name)
    carriage = SpatialInertia(_CARRIAGE_MASS, np.zeros(3), UnitInertia.SolidSphere(0.01))
    parent = plant.world_body()
    links = [plant.AddRigidBody(f"{name}_{axis}_carriage", model, carriage) for axis in "xy"]
    links.append(_add_box_body(plant, model, name))
    parked = OBSTACLE_PARK if name == OBSTACLE else DEBRIS_PARK
    for axis_name, link, axis, park in zip("xyz", links, np.eye(3), parked, strict=True):
        joint = plant.AddJoint(
            PrismaticJoint(
                f"{name}_{axis_name}", parent.body_frame(), link.body_frame(), axis, -2.0, 2.0
            )
        )
        joint.set_default_translation(park)
        plant.AddJointActuator(joint.name(), joint)
        parent = link
    return model


def add_fixed_obstacle(plant: MultibodyPlant) -> FixedOffsetFrame:
    """The planning scene's box, welded to a world frame far below the cell (before
    Finalize); returns that frame, whose pose a layout sets."""
    model = plant.AddModelInstance(OBSTACLE)
    body = _add_box_body(plant, model)
    frame = plant.AddFrame(FixedOffsetFrame(f"{OBSTACLE}_pose", plant.world_frame(), _FAR_BELOW))
    plant.WeldFrames(frame, body.body_frame(), RigidTransform())
    return frame


def far_below() -> RigidTransform:
    """Where the planning scene keeps its box when the cell measures none."""
    return _FAR_BELOW


__all__ = [
    "DEBRIS",
    "DEBRIS_MASS",
    "DEBRIS_PARK",
    "DEBRIS_SIZE",
    "OBSTACLE",
    "OBSTACLE_MASS",
    "OBSTACLE_PARK",
    "OBSTACLE_SEEN_ABOVE",
    "OBSTACLE_SIZE",
    "add_fixed_obstacle",
    "add_mounted_obstacle",
    "far_below",
    "obstacle_pose_over",
]
