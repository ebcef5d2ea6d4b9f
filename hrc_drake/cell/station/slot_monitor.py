"""SlotMonitor: which part sits in which seat, read from the physics of the cell.

A part is in a seat iff it touches that seat's floor geometry (`slot_k_seat` on the plate,
`row_j_seat` on a host part) and its pose is within a tolerance of the seat frame. Nothing else
counts: not the script that placed it, not a commanded pose. Touching is contact; for a pair
whose contact the simulation skips (a bolted part and what it is bolted to,
`hrc_drake.cell.station.welds`), it is the pair's signed distance within `SlotTolerances.touch`.

Every placement also carries the part's measured world pose, whatever its status: a part that
fell on the table, lies askew on the plate or rests in the gripper is found where it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import GeometryId, QueryObject, SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.framework import LeafSystem

from hrc_drake.cell.ports import (
    CellConfiguration,
    PartPlacement,
    PartStatus,
    placement_transform,
    pose_tuple,
)
from hrc_drake.cell.station.contacts import contact_pairs, geometry_owners
from hrc_drake.motion.poses import CellFrames, seat_pose
from hrc_drake.obstacle_models import OBSTACLE, OBSTACLE_SEEN_ABOVE, OBSTACLE_SIZE
from hrc_drake.robot_names import GRIPPER
from hrc_drake.tasks.assembly import SpecError
from hrc_drake.workpiece_sdf import BOSS, PLATE, POCKET_CLEARANCE, POCKET_DEPTH

# A seated part is in its pocket: its boss(es) can stand off the seat by the pocket's clearance
# along each side (cell_models: POCKET_CLEARANCE), no more; the little above that allows for the
# contact's compliance. A part whose boss stands on the pocket's rim is POCKET_DEPTH high.
_SEAT_SLACK = 0.0003  # m


@dataclass(frozen=True)
class SlotTolerances:
    """How close to a frame a part must be. The seat tolerances are what the pocket allows: a
    part read as seated sits in its pocket (so a bolt, which fixes it where it sits, fixes it
    in its seat), and one off by more is not in it."""

    # m: the clearance on both sides at once (a boss in a pocket's corner).
    seat_xy: float = math.hypot(POCKET_CLEARANCE, POCKET_CLEARANCE) + _SEAT_SLACK
    # m: a quarter of the pocket's depth (a boss on the rim stands a whole depth high).
    seat_z: float = POCKET_DEPTH / 4
    # rad: a part resting on its seat floor lies flat; its underside stands SEAT_GAP above the
    # plate, so a tilt past this puts an end of a 65 mm flange on the plate.
    seat_tilt: float = 0.03
    # rad (modulo pi: the flanges are symmetric): a boss turned this far touches its pocket's
    # walls with its corners (half its length turned by this angle is the clearance).
    seat_yaw: float = 2 * POCKET_CLEARANCE / BOSS[0]
    # m: a part's boss and a seat floor whose contact the simulation skips (a bolted part's,
    # `hrc_drake.cell.station.welds`) touch when they are this close (the hydroelastic margin).
    touch: float = 0.0001
    held_position: float = 0.005
    held_angle: float = 0.1
    tray_position: float = 0.01
    tray_angle: float = 0.2
    host_over_slot: float = 0.01  # a host's row frame over a base slot frame, horizontally


@dataclass(frozen=True)
class SeatGeometry:
    """What the SlotMonitor knows of the cell beside contact: where the seats are on the plate
    (`slots`: slot k -> X_plate_slot, in the plate's body `plate_body`) and on each host part
    (`hosts`: host instance -> its rows, (row frame, X_host_row)), each part's symbol, span and
    grasp frame (X_part_grasp), the gripper's tcp (its body and X_body_tcp; None without the
    robot), the tray homes ((symbol, X_W_home)) and the spec's token of a seated placement
    (`token(part, slots, host)`). A configuration sensor that sees only poses decides from it
    (`hrc_drake.cell.station.camera_verdicts`)."""

    plate_body: int
    slots: tuple[tuple[int, RigidTransform], ...]
    hosts: tuple[tuple[str, tuple[tuple[str, RigidTransform], ...]], ...]
    symbols: dict[str, str]
    spans: dict[str, int]
    grasps: dict[str, RigidTransform]
    tcp: tuple[int, RigidTransform] | None
    homes: tuple[tuple[str, RigidTransform], ...]
    token: Callable[[str, tuple[int, ...], str | None], str | None]


@dataclass(frozen=True)
class _Seat:
    name: str  # frame name, e.g. "slot_2", "row_1"
    body_index: object  # BodyIndex of the body that carries it
    X_BS: RigidTransform  # seat frame in that body
    floor: GeometryId


def pose_error(X_ref: RigidTransform, X: RigidTransform) -> tuple[float, float, float, float]:
    """(horizontal, vertical, tilt, yaw modulo pi) of X relative to X_ref, in X_ref's frame."""
    # One 3x4 matrix and plain floats: the configuration sensor asks this many times a step.
    (r00, _, _, px), (r10, _, _, py), (_, _, r22, pz) = X_ref.InvertAndCompose(X).GetAsMatrix34()
    tilt = math.acos(min(max(float(r22), -1.0), 1.0))
    yaw = math.atan2(r10, r00)
    yaw_mod = abs((yaw + math.pi / 2) % math.pi - math.pi / 2)
    return float(math.hypot(px, py)), abs(float(pz)), tilt, yaw_mod


def rotation_angle(X_ref: RigidTransform, X: RigidTransform) -> tuple[float, float]:
    """(distance, rotation angle) of X from X_ref."""
    X_rel = X_ref.InvertAndCompose(X)
    angle = X_rel.rotation().ToAngleAxis().angle()
    return float(np.linalg.norm(X_rel.translation())), float(angle)


def _instance(plant: MultibodyPlant, name: str, role: str):
    if not plant.HasModelInstanceNamed(name):
        known = ", ".join(
            plant.GetModelInstanceName(ModelInstanceIndex(i))
            for i in range(plant.num_model_instances())
        )
        raise ValueError(
            f"SlotMonitor: {role} {name!r} is not a model instance of the plant (instances: "
            f"{known}); build the plant from the same CellDesign as the frames"
        )
    return plant.GetModelInstanceByName(name)


def _named_geometries(plant: MultibodyPlant, inspector, body) -> dict[str, GeometryId]:
    return {
        inspector.GetName(g).split("::")[-1]: g for g in plant.GetCollisionGeometriesForBody(body)
    }


def _seats_of(plant: MultibodyPlant, inspector, model, body) -> list[_Seat]:
    """The seats of a body: each collision geometry `<frame>_seat` is the floor of frame
    `<frame>`."""
    seats = []
    for geometry_name, gid in sorted(_named_geometries(plant, inspector, body).items()):
        if geometry_name.endswith("_seat"):
            frame_name = geometry_name.removesuffix("_seat")
            frame = plant.GetFrameByName(frame_name, model)
            seats.append(_Seat(frame_name, body.index(), frame.GetFixedPoseInBodyFrame(), gid))
    return seats


class SlotMonitor(LeafSystem):
    """Reports the placement of every part from contact results and body poses.

    Input ports: `contact_results` (ContactResults), `body_poses` (list of RigidTransform, by
    BodyIndex), both from the MultibodyPlant; `query_object` (the SceneGraph's, optional: with
    it, a part's boss and a seat floor whose contact is filtered out touch when they are within
    `touch` of each other). Output ports: `slot_configuration` (CellConfiguration: every part's
    status and its body's world pose, read from `body_poses`); `held_part` (str: the part
    `slot_configuration` reads as held, "" for none, found without reading every seat).

    Args:
        plant: the finalized cell plant.
        scene_graph: its SceneGraph (for geometry names).
        frames: the cell's frames and design: which instances are parts of which spec symbol,
            which are hosts, where the tray homes are; tokens are the spec's
            (`AssemblySpec.placement_of`).
        tolerances: pose tolerances.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        scene_graph: SceneGraph,
        frames: CellFrames,
        tolerances: SlotTolerances | None = None,
    ):
        super().__init__()
        self._tol = tolerances if tolerances is not None else SlotTolerances()
        design = frames.design
        self._spec = design.spec
        self._symbols = {p.name: p.symbol for p in design.parts}
        inspector = scene_graph.model_inspector()
        self._read_plate(plant, inspector)
        self._read_parts(plant, inspector, design.host_tags, frames.grasps)
        # The tray is welded: its homes are fixed world poses.
        self._homes = [(self._symbols[part], X_WH) for part, X_WH in frames.homes.items()]
        self._read_gripper(plant)
        self._index_seats()
        self._obstacle = None
        if plant.HasModelInstanceNamed(OBSTACLE):
            model = plant.GetModelInstanceByName(OBSTACLE)
            self._obstacle = int(plant.GetBodyByName(OBSTACLE, model).index())
        self._contacts = self.DeclareAbstractInputPort(
            "contact_results", AbstractValue.Make(ContactResults())
        )
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self._query = self.DeclareAbstractInputPort(
            "query_object", AbstractValue.Make(QueryObject())
        )
        self.DeclareAbstractOutputPort(
            "slot_configuration",
            lambda: AbstractValue.Make(CellConfiguration()),
            self._calc_configuration,
        )
        self.DeclareAbstractOutputPort(
            "held_part", lambda: AbstractValue.Make(""), self._calc_held_part
        )

    def _read_plate(self, plant: MultibodyPlant, inspector) -> None:
        plate = _instance(plant, PLATE, "the base plate")
        body = plant.GetBodyByName(PLATE, plate)
        self._slots = {
            int(s.name.removeprefix("slot_")): s for s in _seats_of(plant, inspector, plate, body)
        }
        if not self._slots:
            raise ValueError("SlotMonitor: the base plate has no slot_k_seat collision geometry")
        self._plate_geometries = set(plant.GetCollisionGeometriesForBody(body))

    def _read_parts(self, plant: MultibodyPlant, inspector, host_tags, grasps) -> None:
        self._parts: dict[str, object] = {}  # instance -> body
        self._part_geometries: dict[str, set[GeometryId]] = {}
        self._bosses: dict[str, list[GeometryId]] = {}
        self._span: dict[str, int] = {}
        # The gripper's tcp in the part's body when it holds the part (CellFrames.grasps).
        self._X_BG: dict[str, RigidTransform] = {}
        # Geometry -> the part instance it belongs to (parts are one body each).
        self._owner = {
            gid: owner.model
            for gid, owner in geometry_owners(plant).items()
            if owner.model in self._symbols
        }
        for name in sorted(self._symbols):
            model = _instance(plant, name, "part")
            body = plant.get_body(plant.GetBodyIndices(model)[0])
            self._parts[name] = body
            self._part_geometries[name] = set(plant.GetCollisionGeometriesForBody(body))
            self._bosses[name] = [
                g for n, g in _named_geometries(plant, inspector, body).items() if n[:4] == "boss"
            ]
            self._span[name] = self._spec.part(self._symbols[name]).footprint
            if name in grasps:
                self._X_BG[name] = grasps[name]
        self._host_seats = {
            name: _seats_of(plant, inspector, plant.GetModelInstanceByName(name), self._parts[name])
            for name in host_tags
        }

    def _index_seats(self) -> None:
        # What every reading asks of the fixed cell, worked out once: the plate's and the
        # parts' body indices, every seat floor with the host it is on, each span's runs of
        # consecutive base slots, and the spec's tokens (asked once per placement).
        self._plate_index = int(next(iter(self._slots.values())).body_index)
        self._part_index = {part: int(body.index()) for part, body in self._parts.items()}
        self._floors = [(None, s.floor) for s in self._slots.values()]
        self._floors += [(host, s.floor) for host, seats in self._host_seats.items() for s in seats]
        slots = sorted(self._slots)
        self._runs: dict[int, list[tuple[tuple[int, ...], list[_Seat]]]] = {}
        for span in set(self._span.values()):
            runs = (tuple(slots[start : start + span]) for start in range(len(slots) - span + 1))
            self._runs[span] = [
                (run, [self._slots[k] for k in run]) for run in runs if run[-1] - run[0] == span - 1
            ]
        self._tokens: dict[tuple[str, tuple[int, ...], str | None], str | None] = {}
        # The seat frames in the world for the last plate pose read (the plate stands still:
        # its pose is the same to the last bit step after step), by the pose's bytes.
        self._plate_key = b""
        self._slot_frames: dict[int, RigidTransform] = {}
        self._nominal: dict[tuple[int, ...], RigidTransform] = {}

    def _nominal_pose(self, run: tuple[int, ...], X_W_plate: RigidTransform) -> RigidTransform:
        """`seat_pose` of the base slots `run` on the plate at `X_W_plate`."""
        frames = self._plate_frames(X_W_plate)
        X_W_nominal = self._nominal.get(run)
        if X_W_nominal is None:
            X_W_nominal = seat_pose({k: frames[k] for k in run}, run)
            self._nominal[run] = X_W_nominal
        return X_W_nominal

    def _plate_frames(self, X_W_plate: RigidTransform) -> dict[int, RigidTransform]:
        """Slot k -> its seat frame in the world, the plate at `X_W_plate`."""
        key = X_W_plate.GetAsMatrix34().tobytes()
        if key != self._plate_key:
            self._plate_key, self._nominal = key, {}
            self._slot_frames = {k: X_W_plate @ s.X_BS for k, s in self._slots.items()}
        return self._slot_frames

    def _read_gripper(self, plant: MultibodyPlant) -> None:
        self._tcp = None
        self._finger_geometries: list[set[GeometryId]] = []
        if not plant.HasModelInstanceNamed(GRIPPER):
            return
        rg2 = plant.GetModelInstanceByName(GRIPPER)
        tcp = plant.GetFrameByName("tcp", rg2)
        self._tcp = (tcp.body().index(), tcp.GetFixedPoseInBodyFrame())
        for body_index in plant.GetBodyIndices(rg2):
            body = plant.get_body(body_index)
            if "finger" in body.name():
                self._finger_geometries.append(set(plant.GetCollisionGeometriesForBody(body)))

    @property
    def part_symbols(self) -> dict[str, str]:
        """Model instance -> spec part symbol."""
        return dict(self._symbols)

    def seat_geometry(self) -> SeatGeometry:
        """The cell's seats, homes and grasps as this monitor reads them (see SeatGeometry)."""
        return SeatGeometry(
            plate_body=self._plate_index,
            slots=tuple((k, seat.X_BS) for k, seat in sorted(self._slots.items())),
            hosts=tuple(
                (host, tuple((seat.name, seat.X_BS) for seat in seats))
                for host, seats in self._host_seats.items()
            ),
            symbols=dict(self._symbols),
            spans=dict(self._span),
            grasps=dict(self._X_BG),
            tcp=None if self._tcp is None else (int(self._tcp[0]), self._tcp[1]),
            homes=tuple(self._homes),
            token=self._token,
        )

    def _touches(self, contacts: ContactResults) -> dict[str, set[GeometryId]]:
        touching: dict[str, set[GeometryId]] = {p: set() for p in self._parts}
        owner = self._owner.get
        for a, b in contact_pairs(contacts):
            # Either geometry may be the part's (and both, for two parts touching).
            part = owner(a)
            if part is not None:
                touching[part].add(b)
            part = owner(b)
            if part is not None:
                touching[part].add(a)
        return touching

    def _touch_skipped(
        self, query: QueryObject, touching: dict[str, set[GeometryId]], parts=None
    ) -> None:
        """Add to `touching` the seat floors a part's boss touches where their contact is
        filtered out: within `touch` of each other (a signed-distance query ignores filters);
        for the `parts` named (default: all)."""
        inspector = query.inspector()
        for part in self._bosses if parts is None else parts:
            for boss in self._bosses[part]:
                for host, floor in self._floors:
                    if host == part or floor in touching[part]:
                        continue
                    if not inspector.CollisionFiltered(boss, floor):
                        continue
                    pair = query.ComputeSignedDistancePairClosestPoints(boss, floor)
                    if pair.distance <= self._tol.touch:
                        touching[part].add(floor)

    def _within_seat(self, X_W_seat: RigidTransform, X_W_part: RigidTransform) -> bool:
        xy, z, tilt, yaw = pose_error(X_W_seat, X_W_part)
        t = self._tol
        return xy <= t.seat_xy and z <= t.seat_z and tilt <= t.seat_tilt and yaw <= t.seat_yaw

    def _base_placement(self, part, X_WP, X_W_plate, touching) -> PartPlacement | None:
        for run, seats in self._runs[self._span[part]]:
            if not all(s.floor in touching for s in seats):
                continue
            if self._within_seat(self._nominal_pose(run, X_W_plate), X_WP):
                return PartPlacement(
                    PartStatus.SEATED,
                    seats=tuple(s.name for s in seats),
                    slots=run,
                    token=self._token(part, run, None),
                )
        return None

    def _host_placement(self, part, X_WP, poses, X_W_plate, touching, base) -> PartPlacement | None:
        if self._span[part] != 1:
            return None
        for host, seats in self._host_seats.items():
            if host == part:
                continue
            X_W_host = poses[self._part_index[host]]
            for seat in seats:
                if seat.floor not in touching:
                    continue
                X_W_seat = X_W_host @ seat.X_BS
                if not self._within_seat(X_W_seat, X_WP):
                    continue
                token = None
                slots: tuple[int, ...] = ()
                host_placement = base.get(host)
                if host_placement is not None:
                    # The base slot under this row: the host may sit either way round.
                    for k, X_W_slot in self._plate_frames(X_W_plate).items():
                        p_slot = X_W_slot.translation()
                        d = np.linalg.norm((X_W_seat.translation() - p_slot)[:2])
                        if d <= self._tol.host_over_slot:
                            slots = (k,)
                            token = self._token(part, slots, host)
                return PartPlacement(
                    PartStatus.SEATED, seats=(seat.name,), slots=slots, host=host, token=token
                )
        return None

    def _token(self, part: str, slots: tuple[int, ...], host: str | None) -> str | None:
        """The spec's token for `part` over `slots` (on the base, or on the instance `host`);
        None when the spec has no such placement."""
        key = (part, slots, host)
        if key not in self._tokens:
            host_symbol = None if host is None else self._symbols[host]
            try:
                token = self._spec.placement_of(self._symbols[part], slots, host_symbol).token
            except SpecError:
                token = None
            self._tokens[key] = token
        return self._tokens[key]

    def _held(self, part, X_WP, poses, touching) -> bool:
        if self._tcp is None:
            return False
        if self._finger_geometries and all(f & touching for f in self._finger_geometries):
            return True
        if part not in self._X_BG:
            return False
        body_index, X_BT = self._tcp
        X_W_tcp = poses[int(body_index)] @ X_BT
        distance, angle = rotation_angle(X_W_tcp, X_WP @ self._X_BG[part])
        if distance > self._tol.held_position:
            return False
        # The flanges are symmetric under a half turn about the approach axis.
        return angle <= self._tol.held_angle or abs(angle - math.pi) <= self._tol.held_angle

    def _in_tray(self, part, X_WP) -> bool:
        for symbol, X_WH in self._homes:
            if symbol != self._symbols[part]:
                continue
            xy, z, tilt, yaw = pose_error(X_WH, X_WP)
            if math.hypot(xy, z) <= self._tol.tray_position and max(tilt, yaw) <= (
                self._tol.tray_angle
            ):
                return True
        return False

    def _touching(self, context) -> dict[str, set[GeometryId]]:
        """What each part touches: its contacts, and the seat floors its bosses stand on
        where that contact is filtered out (`_add_skipped`)."""
        touching = self._touches(self._contacts.Eval(context))
        self._add_skipped(context, touching)
        return touching

    def _add_skipped(self, context, touching, parts=None) -> None:
        """`_touch_skipped` for the `parts` named (default: all), where the query is wired."""
        if self._query.HasValue(context):
            self._touch_skipped(self._query.Eval(context), touching, parts)

    def _calc_held_part(self, context, output) -> None:
        # The status `_calc_configuration` gives, for the one part it could read as held:
        # in the gripper by `_held` (the fingers' contacts are never filtered out, so the
        # plain contacts tell) and seated neither on the plate nor on a host. A run's safety
        # check samples this at every monitor step, where the whole reading cost a
        # millisecond.
        poses = self._poses.Eval(context)
        touching = self._touches(self._contacts.Eval(context))
        for part, index in self._part_index.items():
            X_WP = poses[index]
            if not self._held(part, X_WP, poses, touching[part]):
                continue
            self._add_skipped(context, touching, (part,))
            X_W_plate = poses[self._plate_index]
            mine = touching[part]
            if self._base_placement(part, X_WP, X_W_plate, mine) is None and (
                self._host_placement(part, X_WP, poses, X_W_plate, mine, {}) is None
            ):
                output.set_value(part)
                return
        output.set_value("")

    def _calc_configuration(self, context, output) -> None:
        poses = self._poses.Eval(context)
        touching = self._touching(context)
        X_W_plate = poses[self._plate_index]
        placements: dict[str, PartPlacement] = {}
        for part, index in self._part_index.items():
            found = self._base_placement(part, poses[index], X_W_plate, touching[part])
            if found is not None:
                placements[part] = found
        for part, index in self._part_index.items():
            if part in placements:
                continue
            X_WP = poses[index]
            mine = touching[part]
            found = self._host_placement(part, X_WP, poses, X_W_plate, mine, placements)
            if found is not None:
                placements[part] = found
            elif self._held(part, X_WP, poses, mine):
                placements[part] = PartPlacement(PartStatus.HELD)
            elif mine & self._plate_geometries or any(
                mine & self._part_geometries[h] for h in self._host_seats if h != part
            ):
                placements[part] = PartPlacement(PartStatus.MISPLACED)
            elif self._in_tray(part, X_WP):
                placements[part] = PartPlacement(PartStatus.TRAY)
            else:
                placements[part] = PartPlacement(PartStatus.TRANSIT)
        # Wherever a part is, the sensor reports where: the body pose, whatever the status.
        measured = {
            part: replace(placement, pose=pose_tuple(poses[self._part_index[part]]))
            for part, placement in placements.items()
        }
        output.set_value(CellConfiguration(tuple(sorted(measured.items())), self._seen(poses)))

    def _seen(self, poses) -> tuple[float, ...]:
        """The obstacle's pose if it is in the work (its bottom above the parked height)."""
        if self._obstacle is None:
            return ()
        X_W_obstacle = poses[self._obstacle]
        bottom = X_W_obstacle.translation()[2] - OBSTACLE_SIZE[2] / 2
        return pose_tuple(X_W_obstacle) if bottom > OBSTACLE_SEEN_ABOVE else ()


__all__ = [
    "CellConfiguration",
    "PartPlacement",
    "PartStatus",
    "SeatGeometry",
    "SlotMonitor",
    "SlotTolerances",
    "placement_transform",
    "pose_error",
    "pose_tuple",
    "rotation_angle",
]
