"""The station's safety-rated sensor: units of 3D safety cameras over the desk
(`safety.sensor`), each a frame of rays every 1/`frame_rate` s, what the safety function reads
in place of any body tracker (`hrc_drake.cell.volumetric` is the geometry).

Each frame meets what is there: the simulated person's body, the arm (its shapes posed at the
arm's state, with the part its gripper's opening says it holds) and the table. A frame taken at
t reaches the output at t + `response_time` − 1/`frame_rate` (the unit's response time spans its
frame). The output (`safety_sensor.body`) is the volume no unit saw free and a person could
have come to (`SafetySensor`), less what the robot's shapes from its encoders (grown by
`margin`) and the fixed objects explain, with the points the rays met, as body spheres at
rest. `safety_sensor.ok` is 0 while some unit's newest frame is older than its response time
(a unit that stopped sending, or the `safety_sensor.silent` input: a fault), which the safety
function takes as a safeguard stop.

The person's values reach the function only through the rays: the function never reads the
tracker, nor the simulated body's own ports.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell import volumetric
from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope, primitive
from hrc_drake.cell.ssm import NEAR_SPEED
from hrc_drake.cell.station.safety_function import payload
from hrc_drake.cell_models import TABLE_HALF, TABLE_POSITION, CellModelError
from hrc_drake.robot_names import GRIPPER, UR3, UR3_JOINTS
from hrc_drake.scenario.safety import SafetySensorConfig
from hrc_drake.workpiece_sdf import PLATE, TRAY

_N = len(UR3_JOINTS)
# The robot's shapes as chains of spheres this far apart, for the rays and the mask (our
# choice: the UR3's links are 6-10 cm thick, so each chain sphere bulges a cm or two).
COVER_SPACING = 0.05  # m
# A time-of-flight depth's error (our assumption, the centimetre class of 3D ToF cameras): a ray
# marks a voxel seen free only where it passed this far short of what it met, and each point it
# met stands for a sphere of this radius.
DEPTH_NOISE = 0.01  # m
DEPTH_TOLERANCE = DEPTH_NOISE


@dataclass(frozen=True, eq=False)
class Frame:
    """One unit's frame: taken at `time` [s]; the voxels it saw free (a flat boolean over the
    grid) and the points its rays met something at (k×3, world); the arm's joints `q` and the
    gripper's `opening` its encoders read then."""

    time: float
    free: np.ndarray
    points: np.ndarray
    q: np.ndarray
    opening: float

    def __deepcopy__(self, memo) -> Frame:
        return self


def fixed_objects(plant, scene_graph, instances, grid: volumetric.VoxelGrid, bins) -> np.ndarray:
    """The voxels (flat booleans) the fixed objects explain: the table's top layer, the plate and
    the tray each with the tallest part standing on it, and the operator's `bins`
    (`hrc_drake.layout.BinLayout`), each box grown by half a voxel."""
    context = plant.CreateDefaultContext()
    inspector = scene_graph.model_inspector()
    boxes, tallest = [], 0.0
    for name, model in instances.items():
        for index in plant.GetBodyIndices(model):
            body = plant.get_body(index)
            X_WB = plant.EvalBodyPoseInWorld(context, body)
            for geometry in plant.GetCollisionGeometriesForBody(body):
                X_GC, half, disc, rounding = primitive(inspector.GetShape(geometry))
                X_WC = X_WB @ inspector.GetPoseInFrame(geometry) @ X_GC
                low, high = _aabb(X_WC, half + np.array([disc, disc, 0.0]) + rounding)
                if name in (PLATE, TRAY):
                    boxes.append((low, high))
                elif name not in (UR3, GRIPPER):
                    tallest = max(tallest, float(np.max(high - low)))
    boxes = [(low, high + np.array([0.0, 0.0, tallest])) for low, high in boxes]
    for item in bins:
        size = np.asarray(item.size, dtype=float)
        centre = np.array([item.position[0], item.position[1], size[2] / 2])
        boxes.append((centre - size / 2, centre + size / 2))
    centres = grid.centres()
    fixed = centres[:, 2] < grid.lower[2] + grid.pitch  # the table's top layer
    grow = grid.pitch / 2
    for low, high in boxes:
        fixed |= np.all((centres >= low - grow) & (centres <= high + grow), axis=1)
    return fixed


def _aabb(X_WC: RigidTransform, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    R = np.abs(X_WC.rotation().matrix())
    reach = R @ half
    return X_WC.translation() - reach, X_WC.translation() + reach


@dataclass(frozen=True, eq=False)
class SensorState:
    """The sensor's state: each unit's frame on its way (None: none), when each unit's newest
    delivered frame was taken [s], the voxels a person may hold (`possible`, a flat boolean),
    when they were last fused, and the body reading they give."""

    pending: tuple[Frame | None, ...]
    taken: tuple[float, ...]
    possible: np.ndarray
    fused_at: float
    body: BodySpheres = NOBODY

    def __deepcopy__(self, memo) -> SensorState:
        return self


class SafetySensor(LeafSystem):
    """The safety-rated sensor (see the module docstring).

    Every 1/`frame_rate` s each unit takes a frame; `response_time` − 1/`frame_rate` s later
    the frames are fused. A voxel no frame saw free may hold a person only if a person could
    have come there since the last fusion (ISO 13855's 2.0 m/s from a voxel that might hold
    one), or a ray met something there: volume hidden all along counts as occupied, volume that
    was seen empty and is now in the arm's shadow does not, as a person cannot pass through
    seen space unseen (the sensor powers up with everything unseen occupied).

    Input ports: `body.truth` (BodySpheres: the simulated person, what the rays meet),
    `ur3.state` (12: the arm as it is, which its encoders read), `rg2.state` (2: the
    gripper's measured opening), `safety_sensor.silent` (one per unit, 1: the unit sends no
    frames; unconnected, none is silent).
    Output ports: `safety_sensor.body` (BodySpheres), `safety_sensor.ok` (1)."""

    def __init__(
        self,
        config: SafetySensorConfig,
        envelope: RobotEnvelope,
        widths,
        fixed: np.ndarray,
        grid: volumetric.VoxelGrid,
        table: tuple[float, float, float, float],
    ):
        super().__init__()
        self._config, self._envelope, self._widths = config, envelope, dict(widths)
        self._grid, self._fixed, self._table = grid, fixed, table
        self._units = config.units
        self._rays = [
            volumetric.unit_rays(
                u.name, u.position, u.target, tuple(u.field_of_view), u.reach, u.detection, grid
            )
            for u in self._units
        ]
        self._check_coverage()
        self._covers: dict = {}
        self._truth = self.DeclareAbstractInputPort("body.truth", AbstractValue.Make(NOBODY))
        self._arm = self.DeclareVectorInputPort("ur3.state", 2 * _N)
        self._gripper = self.DeclareVectorInputPort("rg2.state", 2)
        self._silent = self.DeclareVectorInputPort("safety_sensor.silent", len(self._units))
        n = len(self._units)
        initial = SensorState((None,) * n, (-np.inf,) * n, np.ones(grid.size, dtype=bool), 0.0)
        self._state = self.DeclareAbstractState(AbstractValue.Make(initial))
        tickets = {self.abstract_state_ticket(self._state), self.time_ticket()}
        self.DeclareAbstractOutputPort(
            "safety_sensor.body",
            lambda: AbstractValue.Make(NOBODY),
            lambda context, out: out.set_value(self._now(context).body),
            prerequisites_of_calc={self.abstract_state_ticket(self._state)},
        )
        self.DeclareVectorOutputPort(
            "safety_sensor.ok", BasicVector(1), self._calc_ok, prerequisites_of_calc=tickets
        )
        period = 1.0 / self._units[0].frame_rate
        self._latency = config.response_time - period
        self.DeclareInitializationUnrestrictedUpdateEvent(self._power_on)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._take)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, self._latency, self._deliver)

    def _check_coverage(self) -> None:
        """CellModelError if some of the monitored space lies outside every unit's view of the
        empty cell: it would count as occupied for ever."""
        empty = volumetric.Occluders(np.zeros((0, 3)), np.zeros(0), self._table)
        seen = self._fixed.copy()
        for rays in self._rays:
            depth, hit = volumetric.cast(rays, empty)
            seen |= volumetric.view(rays, depth, hit, self._grid, DEPTH_TOLERANCE)[0]
        if not seen.all():
            unseen = self._grid.centres(np.flatnonzero(~seen))
            raise CellModelError(
                f"safety.sensor: {len(unseen)} of the monitored space's {self._grid.size} "
                f"voxels lie outside every unit's view (e.g. around "
                f"{np.round(unseen[0], 2).tolist()} m) and would count as occupied for ever: "
                "aim the units (`safety.sensor.units`) at them or shrink `safety.sensor.space`"
            )

    @property
    def grid(self) -> volumetric.VoxelGrid:
        """The monitored space's voxels."""
        return self._grid

    def _now(self, context) -> SensorState:
        return context.get_abstract_state(self._state).get_value()

    def _power_on(self, context, state) -> None:
        # The sensor runs before the cell starts: frames of the scene as it starts, fused at
        # once, with all it has not seen possibly occupied.
        frames = [self._frame(context, k) for k in range(len(self._units))]
        now = context.get_time()
        frames = [replace(f, time=now - self._latency) for f in frames]
        fused = self._fuse(self._now(context), frames, now)
        state.get_mutable_abstract_state(self._state).set_value(fused)

    def _take(self, context, state) -> None:
        silent = self._silent.HasValue(context) and self._silent.Eval(context)
        pending = tuple(
            None if silent is not False and silent[k] > 0.5 else self._frame(context, k)
            for k in range(len(self._units))
        )
        now = self._now(context)
        state.get_mutable_abstract_state(self._state).set_value(replace(now, pending=pending))

    def _deliver(self, context, state) -> None:
        now = self._now(context)
        fused = self._fuse(now, list(now.pending), context.get_time())
        state.get_mutable_abstract_state(self._state).set_value(fused)

    def _frame(self, context, k: int) -> Frame:
        x = self._arm.Eval(context)
        q, opening = np.array(x[:_N]), float(self._gripper.Eval(context)[0])
        robot = self._robot(q, opening)
        body: BodySpheres = self._truth.Eval(context) if self._truth.HasValue(context) else NOBODY
        n = len(body.radii)
        groups = (*(body.groups or ((0, n),)), *((n + a, n + b) for a, b in robot[2]))
        occluders = volumetric.Occluders(
            np.vstack([body.centres, robot[0]]),
            np.concatenate([body.radii, robot[1]]),
            self._table,
            groups,
        )
        rays = self._rays[k]
        depth, hit = volumetric.cast(rays, occluders)
        free, points = volumetric.view(rays, depth, hit, self._grid, DEPTH_TOLERANCE)
        return Frame(context.get_time(), free, points, q, opening)

    def _robot(self, q: np.ndarray, opening: float) -> tuple[np.ndarray, np.ndarray, tuple]:
        """The robot's cover spheres (world centres, radii, and their groups by body) at `q`
        and `opening`, with the part the opening says it holds."""
        carrying = payload(opening, self._widths)
        found = self._covers.get(carrying)
        if found is None:
            cover = volumetric.cover(self._envelope.shapes(carrying, True), COVER_SPACING)
            # The cover's spheres by body, each body's a group for the rays (`cast`).
            cuts = [0, *(np.flatnonzero(np.diff(cover[0])) + 1), len(cover[0])]
            found = self._covers[carrying] = (cover, tuple(itertools.pairwise(cuts)))
        cover, groups = found
        return (*volumetric.posed(cover, *self._envelope.pose(q, opening)), groups)

    def _calc_ok(self, context, output) -> None:
        now, taken = context.get_time(), self._now(context).taken
        fresh = all(
            now - t <= unit.response_time + 1e-9 for t, unit in zip(taken, self._units, strict=True)
        )
        output.SetFromVector([1.0 if fresh else 0.0])

    def _fuse(self, state: SensorState, arrived: list[Frame | None], now: float) -> SensorState:
        """`state` after fusing the frames `arrived` (one per unit, None: none came) at `now`:
        what a person may hold (see the class docstring), less what the robot at any frame's
        encoders (it stood at one of them) or the fixed objects explain, as the function's
        body reading."""
        grid = self._grid
        taken = tuple(t if f is None else f.time for t, f in zip(state.taken, arrived, strict=True))
        frames = [f for f in arrived if f is not None]
        seen = np.zeros(grid.size, dtype=bool)
        for frame in frames:
            seen |= frame.free
        points = np.vstack([np.zeros((0, 3)), *(f.points for f in frames)])
        poses = {(f.q.tobytes(), f.opening): f for f in frames}
        robots = [self._robot(f.q, f.opening) for f in poses.values()]
        robot = (
            np.vstack([np.zeros((0, 3)), *(r[0] for r in robots)]),
            np.concatenate([np.zeros(0), *(r[1] for r in robots)]),
        )
        reach = volumetric.dilate(grid, state.possible, NEAR_SPEED * (now - state.fused_at))
        flat, points, met = volumetric.unexplained(
            grid, seen, points, robot, self._config.margin, self._fixed, reach
        )
        possible = np.zeros(grid.size, dtype=bool)
        possible[flat] = True
        possible[met] = True
        stamp = min((f.time for f in frames), default=state.fused_at)
        body = volumetric.as_body(
            grid,
            volumetric.surface(grid, flat),
            points,
            DEPTH_NOISE,
            self._config.head_above,
            stamp,
        )
        return SensorState((None,) * len(taken), taken, possible, now, body)


def add_safety_sensor(builder, plant, scene_graph, instances, scenario, frames, body_port):
    """The scenario's safety sensor in the station, reading the simulated person `body_port`
    (None: nobody), the arm's state and the gripper's measured opening, its body and its
    `ok` into the safety function. Returns the sensor (None with `safety.sensor.enabled`
    off)."""
    config = scenario.safety.sensor
    if not config.enabled:
        return None
    grid = volumetric.VoxelGrid.spanning(*config.space, config.voxel)
    fixed = fixed_objects(plant, scene_graph, instances, grid, frames.design.layout.bins)
    sensor = builder.AddNamedSystem(
        "safety_sensor",
        SafetySensor(config, RobotEnvelope(frames.design), frames.widths, fixed, grid, _table()),
    )
    function = builder.GetSubsystemByName("safety_function")
    arm = plant.get_state_output_port(plant.GetModelInstanceByName(UR3))
    builder.Connect(arm, sensor.GetInputPort("ur3.state"))
    gripper = builder.GetSubsystemByName("rg2_measure").get_output_port(0)
    builder.Connect(gripper, sensor.GetInputPort("rg2.state"))
    if body_port is not None:
        builder.Connect(body_port, sensor.GetInputPort("body.truth"))
    body = sensor.GetOutputPort("safety_sensor.body")
    builder.Connect(body, function.GetInputPort("operator.body"))
    builder.Connect(sensor.GetOutputPort("safety_sensor.ok"), function.GetInputPort("sensor_ok"))
    return sensor


def _table() -> tuple[float, float, float, float]:
    """The table's top as (x0, x1, y0, y1) in world (`hrc_drake.cell_models`)."""
    x, y, _ = TABLE_POSITION
    return (x - TABLE_HALF, x + TABLE_HALF, y - TABLE_HALF, y + TABLE_HALF)


__all__ = [
    "COVER_SPACING",
    "DEPTH_NOISE",
    "DEPTH_TOLERANCE",
    "Frame",
    "SafetySensor",
    "SensorState",
    "add_safety_sensor",
    "fixed_objects",
]
