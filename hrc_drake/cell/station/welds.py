"""Bolts: what only the simulated station does to fix a part where it sits (simulator only).

A real cell fixes a placed part with bolts; the simulated operator bolts it too, and the station
then holds the part where it sits at that moment, relative to what it sits on (the plate, or the
host part whose row it is in): never at the nominal seat. (The gripper holds a part by its
fingers' contact and friction alone: `hrc_drake.cell.station.gripper`.)

A bolt locks the part's floating joint (SAP's joint locking, `Joint.Lock`): the part stays
exactly where it is, and its degrees of freedom leave the contact problem. While it holds, the
part's contact with its support is filtered out in the SceneGraph context: the two are one
body, and that contact would cost the step most of its time while changing nothing; the
configuration sensor reads such a filtered pair by distance instead
(`hrc_drake.cell.station.slot_monitor`). A lock fixes the part in the world, which is fixing it
relative to its support while the support does not move: the plate never does, and a host part is
bolted before anything is bolted on it (`hrc_drake.cell.station.sim_operator`) and unbolted only
after (an undo takes the parts off in the reverse order).

Why not weld constraints: Drake 1.51 cannot change a weld constraint's poses once the plant is
finalized, and SAP's weld constraints are compliant: an anchor body welded to a frame whose pose
is a context parameter, held to the part by an identity weld, worked, but at 10 ms steps the
weld gave 0.1-0.5 mm under a flange's weight and the gripper's release.

A Drake system cannot write the plant's context from its events, so the station's `Simulator`
monitor stops the simulation at the step where the wanted bolts change and the runner applies
them (`Bolts.apply`) before it advances again.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from pydrake.geometry import CollisionFilterDeclaration, CollisionFilterManager, GeometrySet
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointIndex

from hrc_drake.cell_models import CellDesign
from hrc_drake.workpiece_sdf import PLATE


@dataclass(frozen=True)
class Weld:
    """A bolt the station wants: `part` fixed where it sits in `seat` (a token on the plate,
    `"<host>/row_<j>"` in a host's row)."""

    part: str
    seat: str

    @property
    def support(self) -> str:
        """The model instance the part is bolted to: the plate, or the host part."""
        return self.seat.split("/", 1)[0] if "/" in self.seat else PLATE

    def __deepcopy__(self, memo) -> Weld:
        return self  # immutable


def _body(plant: MultibodyPlant, model):
    return plant.get_body(plant.GetBodyIndices(model)[0])


def _supports(design: CellDesign, symbol: str) -> list[str]:
    """The model instances a part of `symbol` may be bolted to: the plate if it mounts on the
    base, and every host instance it mounts on."""
    mounts_on = {m.on for m in design.spec.mounts if m.part == symbol}
    supports = [PLATE] if "base" in mounts_on else []
    supports += [p.name for p in design.parts if p.symbol in mounts_on]
    return supports


@dataclass(frozen=True)
class Bolts:
    """What the station bolts with: every part's floating joint, and the collision geometry of
    the part and of each support it may be bolted to."""

    joints: Mapping[str, object]  # part instance -> its floating joint
    supports: Mapping[str, tuple[str, ...]]  # part instance -> what it may be bolted to
    geometries: Mapping[str, GeometrySet]  # part or support instance -> its collision geometry

    @staticmethod
    def of(plant: MultibodyPlant, instances: Mapping[str, object], design: CellDesign) -> Bolts:
        """The bolts of a finalized plant's parts (their floating joints exist then)."""
        bodies = {name: _body(plant, instances[name]) for name in design.instance_names}
        bodies[PLATE] = _body(plant, instances[PLATE])
        joints = {}
        for index in range(plant.num_joints()):
            joint = plant.get_joint(JointIndex(index))
            for name in design.instance_names:
                if joint.child_body().index() == bodies[name].index():
                    joints[name] = joint
        geometries = {
            name: GeometrySet(plant.GetCollisionGeometriesForBody(body))
            for name, body in bodies.items()
        }
        supports = {p.name: tuple(_supports(design, p.symbol)) for p in design.parts}
        return Bolts(joints, supports, geometries)

    def holds(self, weld: Weld) -> bool:
        """Whether `weld` can hold: the part may be bolted to that support."""
        return weld.support in self.supports.get(weld.part, ())

    def bolted(self, plant_context) -> set[str]:
        """The parts bolted (locked) in `plant_context`."""
        return {part for part, joint in self.joints.items() if joint.is_locked(plant_context)}

    def apply(self, plant_context, welds: Iterable[Weld], filters: CollisionFilterManager) -> None:
        """Make exactly `welds` hold in `plant_context` (and the SceneGraph context whose
        collision `filters` these are): a bolt that takes now fixes its part where it sits at
        this moment; one that holds already stays; the others let go. A bolt to a support the
        part cannot be bolted to is skipped (the operator cannot bolt a part where it does not
        fit)."""
        wanted = {w.part: w.support for w in welds if self.holds(w)}
        for part, joint in self.joints.items():
            locked = joint.is_locked(plant_context)
            if part in wanted and not locked:
                joint.Lock(plant_context)
                self._filter(filters, part, [wanted[part]], exclude=True)
            elif part not in wanted and locked:
                joint.Unlock(plant_context)
                self._filter(filters, part, self.supports[part], exclude=False)

    def _filter(self, filters, part: str, supports, exclude: bool) -> None:
        """Filter out (or allow again) the contact between a part and its supports."""
        for support in supports:
            declaration = CollisionFilterDeclaration()
            if exclude:
                declaration.ExcludeBetween(self.geometries[part], self.geometries[support])
            else:
                declaration.AllowBetween(self.geometries[part], self.geometries[support])
            filters.Apply(declaration)


__all__ = ["Bolts", "Weld"]
