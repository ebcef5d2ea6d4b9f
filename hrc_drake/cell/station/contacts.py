"""Who touches whom: the one reading of a plant's contact results.

Both the configuration sensor (which part touches which seat floor) and the collision watch (does
the robot touch anything but the part it handles) ask the same two questions of the simulation:
which geometries are in contact, and which model instance and body own a geometry.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from pydrake.geometry import GeometryId
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex


@dataclass(frozen=True)
class Owner:
    """The model instance and body a collision geometry belongs to."""

    model: str
    body: str


def geometry_owners(plant: MultibodyPlant) -> dict[GeometryId, Owner]:
    """Collision geometry -> its model instance and body name, for every body of `plant`."""
    owners = {}
    for index in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(index))
        owner = Owner(plant.GetModelInstanceName(body.model_instance()), body.name())
        for geometry in plant.GetCollisionGeometriesForBody(body):
            owners[geometry] = owner
    return owners


def contact_pairs(results: ContactResults) -> Iterator[tuple[GeometryId, GeometryId]]:
    """The geometry pairs in contact, hydroelastic and point contact alike (either order)."""
    for i in range(results.num_hydroelastic_contacts()):
        surface = results.hydroelastic_contact_info(i).contact_surface()
        yield surface.id_M(), surface.id_N()
    for i in range(results.num_point_pair_contacts()):
        pair = results.point_pair_contact_info(i).point_pair()
        yield pair.id_A, pair.id_B


def owner_pairs(
    results: ContactResults, owners: dict[GeometryId, Owner]
) -> list[tuple[Owner, Owner]]:
    """The touching pairs of `results` by owner (a pair with a geometry `owners` does not know
    is left out)."""
    pairs = ((owners.get(a), owners.get(b)) for a, b in contact_pairs(results))
    return [(a, b) for a, b in pairs if a is not None and b is not None]


__all__ = ["Owner", "contact_pairs", "geometry_owners", "owner_pairs"]
