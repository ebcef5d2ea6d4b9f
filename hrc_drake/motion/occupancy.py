"""The occupancy rule: room for the gripper and its part among the parts already placed.

The reach check (`hrc_drake.motion.reach_check`) asks whether the arm reaches each grasp in
the empty cell; this asks whether the last stretch of each move has room when the neighbouring
seats are taken. A task picks its part and puts it down along a straight line on the tool's
approach axis (`MotionOptions.approach_distance`, 60 mm), and there the planner keeps the
part and the gripper `clearance` (5 mm) from everything but what the part rests on (its
support: the plate, its host, the tray), which the fingers and the part may touch.

**The rule.** Every move of the spec — a part placed at each seat the spec allows, or undone
from it, and each part picked from or put back in its tray home — has room when the volume
swept by the part and the gripper over that straight stretch (the fingers anywhere from open
around the part, its width + 2 `finger_gap`, to closed on it) keeps at least `clearance` +
`SLACK` from
- every part that may be in place at the same time (`hrc_drake.tasks.occupancy.in_place_with`:
  other slots, the counts, the hosts, the precedence), at its seat, but the part's support;
- the plate, the tray and every other part in the tray, but the support.
Shapes are the collision geometry of the cell's models (generated, or `part_models` files) and
of the gripper at its openings (`hrc_drake.rg2_kinematics`), each bounded by its box along the
world's axes; a box swept along the approach is the box around its two ends. With the plate
and the tray square to the world (turned by multiples of 90°, as the defaults), the boxes are
the generated parts' and the gripper's own shapes (boxes, and cylinders upright); any other
shape or turn makes them larger, so the rule can only ask for more room than a plan needs.
`SLACK` is what the planner's IK may leave its target by (`ik.POSITION_TOLERANCE`, 0.5 mm)
twice over: a neighbour at exactly `clearance` may or may not be planned around.

What it does not cover: the arm above the wrist (the reach check's IK keeps it clear of the
empty cell; it stands 0.2 m above the tool's tip), the free paths between the poses (the
planner's), and parts lying loose after a fault (`hrc_drake.motion.loose_grasp`). Against
exhaustive planning of every edge: benchmarks/bench_occupancy.py.

On the flange case's cell the binding gaps run along the plate's row, between neighbours' ends
(the fingers close across a part, 20 mm wide along the row): an oval flange is 65 mm long and a
two-row host `slot_pitch` + 70 mm, so two oval flanges side by side need a pitch of 71 mm, an
oval flange beside a host 73.5 mm and two hosts side by side 76 mm (at the default 80 mm: 15,
12.5 and 10 mm between them).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform

from hrc_drake.motion.ik import POSITION_TOLERANCE
from hrc_drake.motion.options import MotionOptions
from hrc_drake.motion.poses import CellFrames, offset_along_approach, part_pose
from hrc_drake.motion.scene import (
    GRIPPER,
    MAX_OPENING,
    PLATE,
    TRAY,
    Layout,
    PlanningScene,
    SceneModel,
    part_body,
    shape_support,
)
from hrc_drake.motion.task_move import resolve_task
from hrc_drake.tasks.assembly import AssemblySpec
from hrc_drake.tasks.occupancy import in_place_with
from hrc_drake.tasks.tokens import UNDO

# Room asked beyond `clearance` [m]: the IK's position tolerance, twice.
SLACK = 2 * POSITION_TOLERANCE
# Openings at which the fingers are bounded, evenly from open to closed on the part (the pads
# move on an arc as they close: `hrc_drake.rg2_kinematics`).
_OPENINGS = 4
# Where a part is in the tray (a move's source or target).
IN_TRAY = None


@dataclass(frozen=True)
class Boxes:
    """Axis-aligned boxes: `lo` and `hi` corners (n x 3), each box named by `owner`."""

    lo: np.ndarray
    hi: np.ndarray
    owner: tuple[str, ...]

    @staticmethod
    def join(parts: Iterable[Boxes]) -> Boxes:
        """The boxes of all `parts` together."""
        parts = [p for p in parts if len(p.owner)]
        if not parts:
            return Boxes(np.zeros((0, 3)), np.zeros((0, 3)), ())
        return Boxes(
            np.concatenate([p.lo for p in parts]),
            np.concatenate([p.hi for p in parts]),
            tuple(o for p in parts for o in p.owner),
        )

    def moved(self, X: RigidTransform, owner: str | None = None) -> Boxes:
        """The boxes around these boxes moved by X (renamed `owner`, if given)."""
        pick = [np.array(bits, dtype=bool) for bits in np.ndindex(2, 2, 2)]
        corners = np.stack([np.where(b, self.hi, self.lo) for b in pick], axis=1)  # n x 8 x 3
        world = corners @ X.rotation().matrix().T + X.translation()
        names = self.owner if owner is None else (owner,) * len(self.owner)
        return Boxes(world.min(axis=1), world.max(axis=1), names)

    def hull(self, other: Boxes) -> Boxes:
        """Box by box, the box around this one and `other`'s (the same boxes elsewhere)."""
        return Boxes(np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi), self.owner)

    def nearest(self, other: Boxes) -> tuple[float, str, str]:
        """The least distance between a box of these and one of `other` [m] (0 where they
        overlap), and the owners of the two; (inf, "", "") when `other` is empty."""
        if not len(other.owner) or not len(self.owner):
            return np.inf, "", ""
        gap = np.maximum(
            0.0,
            np.maximum(other.lo[None] - self.hi[:, None], self.lo[:, None] - other.hi[None]),
        )
        distance = np.linalg.norm(gap, axis=2)
        i, j = np.unravel_index(int(np.argmin(distance)), distance.shape)
        return float(distance[i, j]), self.owner[i], other.owner[j]


def _shape_boxes(inspector, geometries, X_F_body: RigidTransform, X_of, owner: str) -> Boxes:
    """The boxes (in frame F) around each collision geometry in `geometries`, whose pose in F
    is `X_of(geometry)`."""
    lo, hi = [], []
    for g in geometries:
        X = X_F_body @ X_of(g)
        R = X.rotation().matrix()
        shape = inspector.GetShape(g)
        up = np.array([shape_support(shape, R.T[:, k]) for k in range(3)])
        down = np.array([shape_support(shape, -R.T[:, k]) for k in range(3)])
        lo.append(X.translation() - down)
        hi.append(X.translation() + up)
    return Boxes(np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3), (owner,) * len(lo))


@dataclass(frozen=True)
class CellGeometry:
    """What the occupancy rule measures: the cell's frames, each part's boxes in its body frame,
    the plate's and the tray's in world, the gripper's around each part's grasp (in the tcp
    frame, over the openings of that grasp), and the room asked (`clearance` + `SLACK`)."""

    frames: CellFrames
    parts: Mapping[str, Boxes]
    fixed: Boxes
    gripper: Mapping[str, Boxes]
    approach: float
    room: float

    @staticmethod
    def of(model: SceneModel, options: MotionOptions) -> CellGeometry:
        """Read from a planning scene model with no part carried (`MotionPlanner`'s)."""
        frames = model.frames
        plant = model.plant
        inspector = model.scene_graph.model_inspector()

        def in_body(g):
            return inspector.GetPoseInFrame(g)

        def boxes_of(instance: str, X_W: RigidTransform) -> Boxes:
            body = part_body(plant, instance)
            geometries = plant.GetCollisionGeometriesForBody(body)
            return _shape_boxes(inspector, geometries, X_W, in_body, instance)

        parts = {i: boxes_of(i, RigidTransform()) for i in frames.design.instance_names}
        fixed = Boxes.join(
            [
                boxes_of(PLATE, frames.design.X_W_plate()),
                boxes_of(TRAY, frames.tray),
            ]
        )
        gripper = {}
        for instance, width in frames.widths.items():
            opened = min(MAX_OPENING, width + 2.0 * options.finger_gap)
            openings = np.linspace(max(width - options.grip_squeeze, 0.0), opened, _OPENINGS)
            gripper[instance] = Boxes.join(
                _gripper_boxes(PlanningScene(model, Layout.of({}, None, float(o))))
                for o in openings
            )
        return CellGeometry(
            frames, parts, fixed, gripper, options.approach_distance, options.clearance + SLACK
        )

    def swept(self, instance: str, X_W_part: RigidTransform) -> Boxes:
        """The boxes `instance` and the gripper holding it sweep from `approach` above X_W_part
        (along the tool's approach axis) down to it."""
        X_W_tcp = X_W_part @ self.frames.grasps[instance]
        X_pre = offset_along_approach(X_W_tcp, self.approach)
        X_tcp_part = self.frames.grasps[instance].inverse()
        part, hand = self.parts[instance], self.gripper[instance]
        return Boxes.join(
            [
                part.moved(X_W_part).hull(part.moved(X_pre @ X_tcp_part)),
                hand.moved(X_W_tcp, GRIPPER).hull(hand.moved(X_pre, GRIPPER)),
            ]
        )

    def at(self, instance: str, X_W_part: RigidTransform, owner: str | None = None) -> Boxes:
        """`instance`'s boxes at X_W_part (named `owner`, default the instance)."""
        return self.parts[instance].moved(X_W_part, owner)


def _gripper_boxes(scene: PlanningScene) -> Boxes:
    """The gripper's collision geometry in a scene (its fingers at the scene's opening), boxed
    in the tcp frame."""
    model = scene.model
    X_tcp_W = scene.tcp_frame.CalcPoseInWorld(scene.plant_context).inverse()
    query = scene.scene_graph.get_query_output_port().Eval(scene.sg_context)
    inspector = query.inspector()
    ids = inspector.GetGeometryIds(model.geometries(GRIPPER))
    return _shape_boxes(inspector, ids, X_tcp_W, query.GetPoseInWorld, GRIPPER)


@dataclass(frozen=True)
class Crowded:
    """A move without room: the part, where it goes (a token, or `IN_TRAY`: its tray home),
    the nearest thing it comes too near, how near [m], and the room the rule asks for."""

    instance: str
    where: str | None
    near: str
    distance: float
    room: float

    @property
    def among_seats(self) -> bool:
        """Whether a part at a seat comes too near another part at a seat (what a larger slot
        pitch gives room for, wherever the plate stands)."""
        return (
            self.where is not IN_TRAY
            and self.near not in (PLATE, TRAY)
            and not self.near.endswith(IN_TRAY_SUFFIX)
        )

    def describe(self, spec: AssemblySpec) -> str:
        """One line: which move comes how near to what."""
        if self.where is IN_TRAY:
            what = f"{self.instance} in its tray home"
        else:
            slots = "-".join(map(str, spec.placement(self.where).slots))
            what = f"{self.where} (slot {slots})"
        return (
            f"placing or taking off {what}, the part and the gripper's fingers on their "
            f"straight way down come {self.distance * 1000:.1f} mm from {self.near}, where the "
            f"planner keeps {self.room * 1000:.1f} mm"
        )


def move_room(
    geometry: CellGeometry,
    instance: str,
    where: str | None,
    X_W_part: RigidTransform,
    obstacles: Boxes,
) -> Crowded | None:
    """Whether `instance` going down to (or up from) X_W_part — at `where`, a token or
    `IN_TRAY` — keeps the rule's room from `obstacles` (its support left out). The nearest
    breach, or None."""
    distance, _mine, near = geometry.swept(instance, X_W_part).nearest(obstacles)
    if distance >= geometry.room:
        return None
    return Crowded(instance, where, near, distance, geometry.room)


IN_TRAY_SUFFIX = " in the tray"


def in_tray_name(instance: str) -> str:
    """How an obstacle that is a part in its tray home is named."""
    return instance + IN_TRAY_SUFFIX


def host_placements(spec: AssemblySpec, token: str) -> list[str]:
    """The host placements a part at `token` may sit on (none for a part on the base)."""
    placement = spec.placement(token)
    if placement.host is None:
        return []
    return [
        t
        for t, m, slots in spec.placements()
        if m.part == placement.host and m.on == "base" and placement.slots[0] in slots
    ]


def _seat_pose(frames: CellFrames, token: str) -> RigidTransform:
    """X_W_part at `token`, on the first host the spec lists for it (a part on a host sits over
    its base slot, on whichever host placement covers it)."""
    return part_pose(frames, token, {token, *host_placements(frames.spec, token)[:1]})


def _fixed_without(geometry: CellGeometry, support: str) -> Boxes:
    fixed = geometry.fixed
    keep = [k for k, o in enumerate(fixed.owner) if o != support]
    return Boxes(fixed.lo[keep], fixed.hi[keep], tuple(fixed.owner[k] for k in keep))


def check_occupancy(geometry: CellGeometry) -> list[Crowded]:
    """The occupancy rule over every move of the spec (module docstring): each token with
    every part that may be in place with it and every other part in the tray, each tray home
    with every other part in the tray and a part at every seat. The breaches, nearest first
    (empty: the layout has room)."""
    frames = geometry.frames
    spec, design = frames.spec, frames.design
    everyone = design.instance_names
    at_seat = {
        t: geometry.at(design.instances_of(spec.placement(t).part)[0], _seat_pose(frames, t), t)
        for t, _m, _s in spec.placements()
    }
    at_home = {i: geometry.at(i, frames.homes[i], in_tray_name(i)) for i in everyone}
    found: list[Crowded] = []
    for token, near in in_place_with(spec).items():
        instance = design.instances_of(spec.placement(token).part)[0]
        support = set(host_placements(spec, token))
        obstacles = Boxes.join(
            [
                *(at_seat[t] for t in sorted(near - support)),
                *(at_home[i] for i in everyone if i != instance),
                _fixed_without(geometry, PLATE if not support else ""),
            ]
        )
        crowded = move_room(geometry, instance, token, _seat_pose(frames, token), obstacles)
        if crowded is not None:
            found.append(crowded)
    seated = list(at_seat.values())
    for instance in everyone:
        others = [at_home[i] for i in everyone if i != instance]
        obstacles = Boxes.join([*others, *seated, _fixed_without(geometry, TRAY)])
        crowded = move_room(geometry, instance, IN_TRAY, frames.homes[instance], obstacles)
        if crowded is not None:
            found.append(crowded)
    return sorted(found, key=lambda c: c.distance)


def edge_room(
    geometry: CellGeometry,
    configuration: Iterable[str],
    task: str,
    last_token: str | None = None,
) -> Crowded | None:
    """The occupancy rule on one task edge, moved as the planner moves it (the robot's own
    routine, `hrc_drake.motion.poses.default_layout`): `task`'s part picked from its tray home
    and put at its seat among `configuration`, or for `undo` the part at `last_token` taken
    off and put back in its tray home. The nearest breach, or None."""
    frames = geometry.frames
    spec = frames.spec
    move = resolve_task(frames, configuration, task, last_token)
    seat = move.source if task == UNDO else move.target
    others = {t: i for t, i in move.before.items() if i != move.instance}
    tokens = set(others) | {seat}
    in_tray = [
        i
        for i in frames.design.instance_names
        if i not in move.after.values() and i != move.instance
    ]
    placed = [geometry.at(i, part_pose(frames, t, tokens), t) for t, i in others.items()]
    homes = [geometry.at(i, frames.homes[i], in_tray_name(i)) for i in in_tray]
    hosts = set(host_placements(spec, seat))
    on_seat = Boxes.join(
        [
            *(
                geometry.at(i, part_pose(frames, t, tokens), t)
                for t, i in others.items()
                if t not in hosts
            ),
            *homes,
            _fixed_without(geometry, PLATE if not hosts else ""),
        ]
    )
    in_home = Boxes.join([*placed, *homes, _fixed_without(geometry, TRAY)])
    for where, X, obstacles in (
        (seat, part_pose(frames, seat, tokens), on_seat),
        (IN_TRAY, frames.homes[move.instance], in_home),
    ):
        crowded = move_room(geometry, move.instance, where, X, obstacles)
        if crowded is not None:
            return crowded
    return None
