"""A kinematic model of the robot for separation monitoring: the robot's collision shapes as convex
primitives, the distance from points to them, and how fast the robot's points move toward them.
The controller's planning monitor (`hrc_drake.cell.controller.separation`), the station's safety
function (`hrc_drake.cell.station.safety_function`) and the run's check each build their own.

Like a real controller or safety controller, each has its own kinematic model: a MultibodyPlant of
the cell parsed from the project's models (`add_cell_models`), of which it uses the UR3, the
gripper and the parts' shapes. At construction every collision shape of the robot, and of each
part as it sits in the gripper (its pads at the part's `grasp` frame, `CellFrames.grasps`),
becomes a convex primitive in numpy (`RobotEnvelope`): a box, a cylinder (a disc swept along z),
a capsule or a sphere, each the shape itself, so the distance from a point is exact; an
ellipsoid or a mesh becomes its enclosing box. The gripper's linkage, when its opening is not
measured, takes the box each of its shapes sweeps over the whole stroke. So the distance is never
more than the true one.

Apart from the monitors because this is geometry and kinematics, the same whatever the standard
asks: `hrc_drake.cell.ssm` turns these distances and speeds into ISO/TS 15066's separation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Box, Capsule, Convex, Cylinder, Ellipsoid, Mesh, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from hrc_drake.cell_models import CellDesign, add_cell_models
from hrc_drake.motion.scene import TCP, read_cell_frames
from hrc_drake.rg2_kinematics import joint_angles
from hrc_drake.robot_models import RG2_JOINTS, RG2_MAX_OPENING, set_rg2_opening
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS

_TINY = 1e-12  # keeps the divisions by a length finite where it vanishes
# The linkage's sweep is taken at this many openings over the stroke; its boxes grow by
# SWEEP_MARGIN, more than a shape's corner strays off its sampled arc between two samples
# (< 0.02 mm: 0.07 m from a pivot, 0.04 rad apart).
SWEEP_SAMPLES = 33
SWEEP_MARGIN = 1e-4  # m
_YZX, _ZXY = [1, 2, 0], [2, 0, 1]


@dataclass(frozen=True)
class Primitives:
    """Convex shapes on the robot's bodies, as arrays over the m shapes.

    A shape is, in its own frame C, the box |x|, |y|, |z| ≤ `half`, swept in x–y by a disc of
    radius `disc` (a cylinder along z when the box is the segment of z), grown by `round` (a
    capsule or a sphere). `body` indexes `RobotEnvelope.bodies` (the pose it moves with), `link`
    the arm link whose motion it shares (`RobotEnvelope.links`; the last row is the fixed base)."""

    names: tuple[str, ...]
    body: np.ndarray
    link: np.ndarray
    R_BC: np.ndarray
    p_BC: np.ndarray
    half: np.ndarray
    disc: np.ndarray
    round: np.ndarray
    _spread: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def spread(self, n: int) -> tuple[np.ndarray, ...]:
        """(half, −half m×3×n; disc, round, disc > 0 m×n): the shapes' sizes laid out against
        n points (`nearest_to_posed`), made once per n."""
        found = self._spread.get(n)
        if found is None:
            m = len(self.names)
            half = np.ascontiguousarray(np.broadcast_to(self.half[:, :, None], (m, 3, n)))
            disc, rounding = (np.repeat(x[:, None], n, axis=1) for x in (self.disc, self.round))
            found = self._spread[n] = (half, -half, disc, rounding, disc > 0.0)
        return found

    @staticmethod
    def join(parts: list[Primitives]) -> Primitives:
        """One set of all the shapes of `parts`."""
        fields = ("body", "link", "R_BC", "p_BC", "half", "disc", "round")
        columns = {f: np.concatenate([getattr(p, f) for p in parts]) for f in fields}
        return Primitives(tuple(n for p in parts for n in p.names), **columns)


def primitive(shape, name: str = "") -> tuple[RigidTransform, np.ndarray, float, float]:
    """(X_GC, half, disc, round) of a collision shape (see `Primitives`): exact for a box,
    cylinder, capsule or sphere; the enclosing box of an ellipsoid or of a mesh's convex hull.
    ValueError names a shape it cannot enclose."""
    origin = RigidTransform()
    if isinstance(shape, Box):
        return origin, np.array([shape.width(), shape.depth(), shape.height()]) / 2, 0.0, 0.0
    if isinstance(shape, Cylinder):
        return origin, np.array([0.0, 0.0, shape.length() / 2]), shape.radius(), 0.0
    if isinstance(shape, Capsule):
        return origin, np.array([0.0, 0.0, shape.length() / 2]), 0.0, shape.radius()
    if isinstance(shape, Sphere):
        return origin, np.zeros(3), 0.0, shape.radius()
    if isinstance(shape, Ellipsoid):
        return origin, np.array([shape.a(), shape.b(), shape.c()]), 0.0, 0.0
    if isinstance(shape, Convex | Mesh):
        hull = shape.GetConvexHull()
        points = np.array([hull.vertex(i) for i in range(hull.num_vertices())])
        low, high = points.min(axis=0), points.max(axis=0)
        return RigidTransform((low + high) / 2), (high - low) / 2, 0.0, 0.0
    raise ValueError(
        f"the separation monitor cannot enclose the {type(shape).__name__} {name!r}: give the "
        "robot or the part a box, cylinder, capsule, sphere, ellipsoid or mesh collision shape"
    )


def _swept(half: np.ndarray, disc: float, rounding: float, moves: list[RigidTransform]):
    """(X_CS, half extents) of the box S that holds a shape (in its frame C) moved by each of
    `moves` (X_C C', C' the shape's frame moved), grown by SWEEP_MARGIN."""
    box = half + np.array([disc, disc, 0.0]) + rounding
    corners = box * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    points = np.vstack([(X.rotation().matrix() @ corners.T).T + X.translation() for X in moves])
    low, high = points.min(axis=0), points.max(axis=0)
    return RigidTransform((low + high) / 2), (high - low) / 2 + SWEEP_MARGIN


class RobotEnvelope:
    """The controller's own model of the robot: a MultibodyPlant of the cell (from the project's
    models and the cell design), its scratch context, and the robot's collision shapes (and each
    part's, as held) as `Primitives`.

    `pose(q, opening)` runs forward kinematics; `shapes(carrying, measured_opening)` is the set to
    measure against. Not thread-safe: one envelope per monitor."""

    def __init__(self, design: CellDesign):
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
        add_cell_models(plant, design)
        plant.Finalize()
        self._diagram = builder.Build()  # owns the plant and the SceneGraph
        self.plant, self.context = plant, plant.CreateDefaultContext()
        inspector = scene_graph.model_inspector()
        arm, gripper = plant.GetModelInstanceByName(UR3), plant.GetModelInstanceByName(GRIPPER)
        self._arm = arm
        self.arm_velocities = np.array(
            [plant.GetJointByName(name, arm).velocity_start() for name in UR3_JOINTS]
        )
        self._gripper = gripper
        self._linkage = {name: plant.GetJointByName(name, gripper) for name in RG2_JOINTS}
        self._sweeps = self._linkage_sweeps()
        robot = [
            plant.get_body(index)
            for model in (arm, gripper)
            for index in plant.GetBodyIndices(model)
            if plant.GetCollisionGeometriesForBody(plant.get_body(index))
        ]
        self.links = [plant.GetJointByName(name, arm).child_body() for name in UR3_JOINTS]
        self.bodies = list({b.index(): b for b in [*robot, *self.links]}.values())
        self._row = {b.index(): i for i, b in enumerate(self.bodies)}
        self._link_rows = np.array([self._row[b.index()] for b in self.links])
        self._tcp = plant.GetFrameByName(TCP, gripper)
        self.tcp_body = self._tcp.body()
        self._robot = {
            swept: Primitives.join([self._body_shapes(inspector, body, swept) for body in robot])
            for swept in (False, True)
        }
        held = read_cell_frames(plant, scene_graph, self.context, design).grasps
        X_B_tcp = self._tcp.GetFixedPoseInBodyFrame()
        # Each part's pose on the tcp's body as the gripper holds it (its pads at the part's
        # grasp frame): its shapes (`shapes`) and its inertia (`effective_mass`) ride there.
        self.held_poses = {p.name: X_B_tcp @ held[p.name].inverse() for p in design.parts}
        self._parts = {
            name: self._part_shapes(inspector, plant.GetModelInstanceByName(name), X_B_part)
            for name, X_B_part in self.held_poses.items()
        }
        self._sets: dict[tuple[str | None, bool], Primitives] = {}
        self._axes, self._points = self._chain()
        self._opening: float | None = None  # the gripper's opening `pose` last set (None: unset)
        self._posed: tuple = (None, None)  # ((q's bytes, opening), (R_WB, p_WB)) `pose` last gave

    def link_of(self, body) -> int:
        """Row in `links` of the arm link whose motion `body` shares; len(links): fixed."""
        plant, names = self.plant, set(UR3_JOINTS)
        while body.index() != plant.world_body().index():
            joint = next(
                plant.get_joint(j)
                for j in plant.GetJointIndices()
                if plant.get_joint(j).child_body().index() == body.index()
            )
            if joint.name() in names and joint.model_instance() == self._arm:
                return [b.index() for b in self.links].index(body.index())
            body = joint.parent_body()
        return len(self.links)

    def _linkage_sweeps(self) -> dict[int, list[RigidTransform]]:
        """Each body the gripper's linkage moves -> its poses over the stroke, relative to its
        pose at mid-stroke (where `pose` puts it when the opening is not measured)."""
        plant, context = self.plant, self.context
        moved = {plant.GetJointByName(name, self._gripper).child_body() for name in RG2_JOINTS}
        base = plant.GetFrameByName("rg2_base", self._gripper)

        def poses(opening: float) -> dict[int, RigidTransform]:
            set_rg2_opening(plant, context, opening, self._gripper)
            return {int(b.index()): b.body_frame().CalcPose(context, base) for b in moved}

        mid = poses(RG2_MAX_OPENING / 2)
        samples = [poses(w) for w in np.linspace(0.0, RG2_MAX_OPENING, SWEEP_SAMPLES)]
        return {i: [X.inverse() @ at[i] for at in samples] for i, X in mid.items()}

    def _body_shapes(self, inspector, body, swept: bool) -> Primitives:
        """The collision shapes of `body`; with `swept`, a linkage body's over the stroke."""
        moves = self._sweeps.get(int(body.index())) if swept else None
        rows = []
        for gid in self.plant.GetCollisionGeometriesForBody(body):
            name = inspector.GetName(gid)
            X_GC, half, disc, rounding = primitive(inspector.GetShape(gid), name)
            X_BC = inspector.GetPoseInFrame(gid) @ X_GC
            if moves is not None:
                # The shape moved with its body, seen from its own frame at mid-stroke.
                X_CS, half = _swept(
                    half, disc, rounding, [X_BC.inverse() @ X @ X_BC for X in moves]
                )
                X_BC, disc, rounding = X_BC @ X_CS, 0.0, 0.0
            rows.append((name, X_BC, half, disc, rounding))
        return self._primitives(rows, self._row[body.index()], self.link_of(body))

    def _part_shapes(self, inspector, model, X_B_part: RigidTransform) -> Primitives:
        """A part's collision shapes as the gripper holds it: on the body of the `tcp` frame,
        the part at `X_B_part` there (`held_poses`)."""
        plant = self.plant
        (index,) = plant.GetBodyIndices(model)
        rows = []
        for gid in plant.GetCollisionGeometriesForBody(plant.get_body(index)):
            name = inspector.GetName(gid)
            X_GC, half, disc, rounding = primitive(inspector.GetShape(gid), name)
            X_BC = X_B_part @ inspector.GetPoseInFrame(gid) @ X_GC
            rows.append((name, X_BC, half, disc, rounding))
        body = self._tcp.body()
        return self._primitives(rows, self._row[body.index()], self.link_of(body))

    @staticmethod
    def _primitives(rows, body: int, link: int) -> Primitives:
        m = len(rows)
        return Primitives(
            names=tuple(r[0] for r in rows),
            body=np.full(m, body, dtype=int),
            link=np.full(m, link, dtype=int),
            R_BC=np.array([r[1].rotation().matrix() for r in rows]).reshape(m, 3, 3),
            p_BC=np.array([r[1].translation() for r in rows]).reshape(m, 3),
            half=np.array([r[2] for r in rows], dtype=float).reshape(m, 3),
            disc=np.array([r[3] for r in rows], dtype=float),
            round=np.array([r[4] for r in rows], dtype=float),
        )

    def shapes(self, carrying: str | tuple[str, ...] | None, measured_opening: bool) -> Primitives:
        """The robot's shapes (fingers as measured, or swept over their travel) and the carried
        part's (a tuple: each of those parts', all in the grasp, as a payload that may be any
        of them). KeyError names the parts if `carrying` is not one."""
        key = (carrying, not measured_opening)
        if key not in self._sets:
            parts = [self._robot[key[1]]]
            for part in (carrying,) if isinstance(carrying, str) else carrying or ():
                if part not in self._parts:
                    raise KeyError(f"no part {part!r}; the parts are {sorted(self._parts)}")
                parts.append(self._parts[part])
            self._sets[key] = Primitives.join(parts)
        return self._sets[key]

    def pose(self, q: np.ndarray, opening: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics at arm positions `q` (UR3_JOINTS order) and the gripper `opening`
        (None: mid-stroke): (R_WB n×3×3, p_WB n×3) of `bodies`."""
        plant, context = self.plant, self.context
        opening = (
            RG2_MAX_OPENING / 2 if opening is None else min(max(opening, 0.0), RG2_MAX_OPENING)
        )
        key = (np.asarray(q, dtype=float).tobytes(), opening)
        if key == self._posed[0]:
            # Asked again at the same pose (the forecast monitor's check far from the body,
            # then its assessment): the kinematics are the same.
            return self._posed[1]
        plant.SetPositions(context, self._arm, q)
        if opening != self._opening:
            # A quantised opening (`sensors:`) seldom changes between two calls; an exact one
            # changes at every call, so the linkage's joints are looked up once, not by name
            # at every set (`set_rg2_opening`'s angles, `rg2_kinematics.joint_angles`).
            for name, angle in joint_angles(opening).items():
                self._linkage[name].set_angle(context, angle)
            self._opening = opening
        X = np.array([plant.EvalBodyPoseInWorld(context, b).GetAsMatrix34() for b in self.bodies])
        X.flags.writeable = False  # shared with the next call at this pose
        self._posed = (key, (X[:, :, :3], X[:, :, 3]))
        return self._posed[1]

    def _chain(self) -> tuple[np.ndarray, np.ndarray]:
        """Each arm joint's axis and a point on it in its link's frame (UR3_JOINTS order), after
        checking that the joints make one serial chain (each moves the previous one's link)."""
        axes, points = [], []
        for row, name in enumerate(UR3_JOINTS):
            joint = self.plant.GetJointByName(name, self._arm)
            parent = self.link_of(joint.parent_body())
            if parent != (row - 1 if row > 0 else len(self.links)):
                raise ValueError(f"the arm's joints are not one serial chain at {name}")
            X_BM = joint.frame_on_child().CalcPoseInBodyFrame(self.context)
            axes.append(X_BM.rotation() @ np.asarray(joint.revolute_axis()))
            points.append(X_BM.translation())
        return np.array(axes), np.array(points)

    def link_velocities(self, R_WB: np.ndarray, p_WB: np.ndarray, velocities) -> np.ndarray:
        """(k, L+1, 2, 3): for each row of arm joint `velocities` (k×6), each link's angular
        velocity ω and the velocity v₀ of the point at the world origin moving with it (a point
        P of the link moves at v₀ + ω × P; last row: the fixed base). Each link's spatial
        velocity Jacobian of the serial chain at the posed bodies: joint j turns about its
        world axis a_j through o_j, adding (a_j, o_j × a_j) q̇_j to every link from j on."""
        R, p = R_WB[self._link_rows], p_WB[self._link_rows]
        axis = np.einsum("lij,lj->li", R, self._axes)
        origin = np.einsum("lij,lj->li", R, self._points) + p
        columns = np.concatenate([axis, cross(origin, axis)], axis=1)  # (L, 6)
        out = np.zeros((len(velocities), len(self.links) + 1, 2, 3))
        out[:, :-1] = np.cumsum(columns[None] * velocities[:, :, None], axis=1).reshape(
            len(velocities), len(self.links), 2, 3
        )
        return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over the last axis (np.cross costs more than the rest of a step here)."""
    return a[..., _YZX] * b[..., _ZXY] - a[..., _ZXY] * b[..., _YZX]


@dataclass(frozen=True)
class Pairs:
    """Every (shape, body sphere) pair of one step: arrays m×n (×3).

    Attributes:
        distance: from the sphere's centre to the shape [m] (negative inside).
        witness: the shape's point nearest the centre, in world [m].
        direction: the unit vector from the shape toward the centre, in world (zero when the
            centre is inside the shape's core).
        link: the row of the shape's link (`RobotEnvelope.link_velocities`), per shape (m).
    """

    distance: np.ndarray
    witness: np.ndarray
    direction: np.ndarray
    link: np.ndarray


def nearest_points(shapes: Primitives, R_WB: np.ndarray, p_WB: np.ndarray, points) -> Pairs:
    """The distance from each of `points` (n×3, world) to each of `shapes` posed by the bodies'
    poses (R_WB, p_WB), and the nearest point on the shape (see `Primitives`)."""
    return nearest_to_posed(shapes, *posed_shapes(shapes, R_WB, p_WB), points)


def posed_shapes(shapes: Primitives, R_WB: np.ndarray, p_WB: np.ndarray):
    """(R_WC m×3×3, p_WC m×3): each of `shapes` in the world, on the bodies posed (R_WB, p_WB)."""
    R = R_WB[shapes.body]
    return R @ shapes.R_BC, (R @ shapes.p_BC[..., None])[..., 0] + p_WB[shapes.body]


def nearest_to_posed(shapes: Primitives, R_WC: np.ndarray, p_WC: np.ndarray, points) -> Pairs:
    """`nearest_points` of `shapes` already posed in the world (`posed_shapes`)."""
    # Laid out shape × axis × point (m×3×n), so that each step below runs over whole rows of
    # points: broadcast over m×n×3, a shape's three numbers cost numpy a loop per pair. Each
    # length is summed in the order np.einsum summed it over m×n×3 ((x² + z²) + y²; x² + y²)
    # and matmul takes the transposed operands, so every figure is as before to the last bit.
    half, neg_half, disc, rounding, has_disc = shapes.spread(len(points))
    p = R_WC.transpose(0, 2, 1) @ (points.T[None, :, :] - p_WC[:, :, None])  # in C
    # Nearest point of the core (box, then the disc across x–y), then of the rounded shape.
    core = np.minimum(np.maximum(p, neg_half), half)
    across = p[:, :2] - core[:, :2]
    length = np.sqrt(across[:, 0] * across[:, 0] + across[:, 1] * across[:, 1])
    core[:, :2] += across * np.minimum(1.0, disc / np.maximum(length, _TINY))[:, None]
    offset = p - core
    x, y, z = offset.transpose(1, 0, 2)
    out = np.sqrt((x * x + z * z) + y * y)
    unit = offset / np.maximum(out, _TINY)[:, None]
    local = core + unit * np.minimum(rounding, out)[:, None]
    # Inside the core: the depth to its nearest face (negative). A shape with a disc has no
    # box across x–y (`primitive`), so `length` is the radial distance there.
    excess = np.abs(p) - half
    lateral = np.where(has_disc, length - disc, np.maximum(excess[:, 0], excess[:, 1]))
    inside = np.minimum(np.maximum(lateral, excess[:, 2]), 0.0)
    # To the world as m×n×3 arrays, as before: the callers' einsum sums by the layout.
    R_CW = R_WC.transpose(0, 2, 1)
    witness = local.transpose(0, 2, 1) @ R_CW
    witness += p_WC[:, None, :]
    return Pairs(out + inside - rounding, witness, unit.transpose(0, 2, 1) @ R_CW, shapes.link)


def speeds_toward(links: np.ndarray, pairs: Pairs) -> np.ndarray:
    """(k, m, n): the speed of each witness point along its pair's direction, for each row of
    link velocities (`RobotEnvelope.link_velocities`): (v_o + ω × w)·d = v_o·d + ω·(w × d)."""
    # Component by component, each dot product summed in the order np.einsum summed it here
    # (v_o·d: (0 + 2) + 1 over a contiguous row; ω·(w × d): 0 + 1 + 2), so every speed is
    # the same to the last bit, without einsum's and fancy indexing's overhead.
    w, d = pairs.witness, pairs.direction
    w0, w1, w2, d0, d1, d2 = w[..., 0], w[..., 1], w[..., 2], d[..., 0], d[..., 1], d[..., 2]
    c0, c1, c2 = w1 * d2 - w2 * d1, w2 * d0 - w0 * d2, w0 * d1 - w1 * d0
    row = links[:, pairs.link, :, :, None]  # k×m×2×3×1: (ω, v_o) of each shape's link
    omega, origin = row[:, :, 0], row[:, :, 1]
    along = (origin[:, :, 0] * d0 + origin[:, :, 2] * d2) + origin[:, :, 1] * d1
    return along + ((omega[:, :, 0] * c0 + omega[:, :, 1] * c1) + omega[:, :, 2] * c2)


__all__ = [
    "Pairs",
    "Primitives",
    "RobotEnvelope",
    "cross",
    "nearest_points",
    "nearest_to_posed",
    "posed_shapes",
    "primitive",
    "speeds_toward",
]
