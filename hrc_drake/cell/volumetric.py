"""Volumetric safety sensing: what safety-rated 3D sensors over the desk see, as numbers.

A unit (a 3D time-of-flight safety camera, `safety.sensor.units`) casts a fan of rays from its
origin and measures, per ray, the depth of the first surface it meets. The monitored space is a
grid of voxels (`VoxelGrid`). A voxel is *seen free* when some unit's ray passes through it short
of that ray's depth; every other voxel of the monitored space is *unknown* (occupied, hidden
behind something, or outside every unit's field), and unknown counts as occupied, as a safety
sensor treats what it cannot see (Veo FreeMove; `shared/reference/safety-and-devices.md`),
where a person could have come (`dilate`: volume seen empty a frame ago, far from anything
possibly occupied, is not). Where a ray met something, the point it met stands for it.

Unknown volume is *explained*, and not a person, where the robot's own shapes (posed from its
encoders, grown by `margin`) or a fixed object (the table, the tray, the plate, the bins) hold
the voxel's centre. The rest is what the safety function keeps its distance from:
`unexplained` gives it as body spheres (one per voxel on the surface of that volume).

Rays are spaced so that anything as wide as the unit's detection capability is met by one at the
far end of the monitored space (a square grid of pitch d/√2: a disc of diameter d always holds
one of its points), as a sensor's resolution is its detection capability at its range. Drake-free.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hrc_drake.cell.ports import BodySpheres

_SQRT3_2 = float(np.sqrt(3.0) / 2.0)
# Groups of the person model's parts (hand, forearm, upper arm, torso, head): a voxel's body
# region is unknown, so below the head's height it is the torso's, the most cautious region
# power and force limiting permits touching (`contact_limits.CHEST`); above it, the head's.
_TORSO, _HEAD = 3, 4


@dataclass(frozen=True)
class VoxelGrid:
    """The monitored space: `shape` voxels of edge `pitch` [m] from the corner `lower` [m]."""

    lower: np.ndarray
    pitch: float
    shape: tuple[int, int, int]

    @staticmethod
    def spanning(lower, upper, pitch: float) -> VoxelGrid:
        """The grid of `pitch` that covers the box from `lower` to `upper` (world, m)."""
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        if pitch <= 0 or np.any(upper <= lower):
            raise ValueError(
                f"the monitored space {lower.tolist()}..{upper.tolist()} with voxels of {pitch} m "
                "is empty: give `safety.sensor.space` a lower corner below its upper one and a "
                "positive `voxel`"
            )
        shape = tuple(int(n) for n in np.ceil((upper - lower) / pitch - 1e-9))
        return VoxelGrid(lower, float(pitch), shape)

    @property
    def size(self) -> int:
        """The number of voxels."""
        return int(np.prod(self.shape))

    @property
    def radius(self) -> float:
        """The radius of the sphere that holds a voxel [m] (half its diagonal)."""
        return self.pitch * _SQRT3_2

    def centres(self, flat: np.ndarray | None = None) -> np.ndarray:
        """The centres (n×3, world) of the voxels `flat` (flat indices; None: every voxel)."""
        flat = np.arange(self.size) if flat is None else np.asarray(flat)
        ijk = np.stack(np.unravel_index(flat, self.shape), axis=-1)
        return self.lower + (ijk + 0.5) * self.pitch

    def index(self, points: np.ndarray) -> np.ndarray:
        """The flat index of the voxel holding each of `points` (n×3); -1 outside the grid."""
        ijk = np.floor((points - self.lower) / self.pitch).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < np.array(self.shape)), axis=-1)
        flat = np.ravel_multi_index(tuple(np.clip(ijk, 0, np.array(self.shape) - 1).T), self.shape)
        return np.where(inside, flat, -1)


@dataclass(frozen=True)
class Occluders:
    """What the rays can meet: spheres (`centres` n×3, `radii` n, world) in `groups` (index
    ranges [start, end), each tested first as a whole: a limb, a robot link) and the table's top
    (the face z = `top` over x, y within `table` = (x0, x1, y0, y1)), which is the taught
    background, not an object in the monitored space."""

    centres: np.ndarray
    radii: np.ndarray
    table: tuple[float, float, float, float]
    groups: tuple[tuple[int, int], ...] = ()
    top: float = 0.0


@dataclass(frozen=True)
class UnitRays:
    """One unit's rays: `origin` (3), unit `directions` (p×3), and, precomputed once, the points
    along them at which a ray marks the voxel it passes through as seen (`sample_ray`,
    `sample_t` [m], `sample_voxel`: the ray, the distance along it, the voxel's flat index)."""

    name: str
    origin: np.ndarray
    directions: np.ndarray
    reach: float
    sample_ray: np.ndarray = field(repr=False)
    sample_t: np.ndarray = field(repr=False)
    sample_voxel: np.ndarray = field(repr=False)


def look_at(origin, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """R_WU (3×3) of a unit at `origin` looking at `target`: its z along the optical axis, its x
    across the wide field (level, unless the unit looks straight down: then world x)."""
    z = np.asarray(target, dtype=float) - np.asarray(origin, dtype=float)
    if np.linalg.norm(z) < 1e-9:
        raise ValueError("a safety sensor unit's `target` must differ from its `position`")
    z /= np.linalg.norm(z)
    x = np.cross(np.asarray(up, dtype=float), z)
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(np.array([0.0, 1.0, 0.0]), z)  # straight down: x along world x
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def unit_rays(
    name: str,
    origin,
    target,
    field_of_view_deg: tuple[float, float],
    reach: float,
    detection: float,
    grid: VoxelGrid,
) -> UnitRays:
    """The rays of a unit at `origin` aimed at `target` (world, m) with the `field_of_view_deg`
    (wide, narrow) and `reach` [m], spaced for the `detection` capability [m] at the farthest
    point of the monitored `grid` within reach (see the module docstring)."""
    origin = np.asarray(origin, dtype=float)
    R = look_at(origin, target)
    corners = grid.lower + np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]) * (
        np.array(grid.shape) * grid.pitch
    )
    far = min(reach, float(np.linalg.norm(corners - origin, axis=1).max()))
    step = (detection / np.sqrt(2.0)) / far  # rad between neighbouring rays
    half = np.radians(np.asarray(field_of_view_deg, dtype=float)) / 2
    counts = np.maximum(2, np.ceil(2 * half / step).astype(int) + 1)
    u = np.tan(np.linspace(-half[0], half[0], counts[0]))
    v = np.tan(np.linspace(-half[1], half[1], counts[1]))
    uu, vv = np.meshgrid(u, v, indexing="xy")
    local = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    directions = local @ R.T
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return _with_samples(name, origin, directions, reach, grid)


def _with_samples(name, origin, directions, reach, grid: VoxelGrid) -> UnitRays:
    """`UnitRays` with the points where each ray crosses the grid, every 3/4 voxel."""
    upper = grid.lower + np.array(grid.shape) * grid.pitch
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (grid.lower - origin) / directions
        t1 = (upper - origin) / directions
    enter = np.nanmax(np.minimum(t0, t1), axis=1).clip(min=0.0)
    leave = np.minimum(np.nanmin(np.maximum(t0, t1), axis=1), reach)
    step = 0.75 * grid.pitch
    rays, ts = [], []
    for ray in np.flatnonzero(leave > enter):
        t = np.arange(enter[ray] + step / 2, leave[ray], step)
        rays.append(np.full(t.size, ray))
        ts.append(t)
    sample_ray = np.concatenate(rays) if rays else np.zeros(0, dtype=int)
    sample_t = np.concatenate(ts) if ts else np.zeros(0)
    voxel = grid.index(origin + sample_t[:, None] * directions[sample_ray])
    keep = voxel >= 0
    return UnitRays(
        name, origin, directions, float(reach), sample_ray[keep], sample_t[keep], voxel[keep]
    )


def _meet(o: np.ndarray, d: np.ndarray, centres: np.ndarray, radii: np.ndarray):
    """(ray row, distance) of each ray of directions `d` from `o` that meets a sphere, per
    sphere met (rows repeat)."""
    oc = centres - o
    # Along-ray distance to each centre's foot, component by component (a k = 3 matmul costs
    # BLAS several times three broadcasts here).
    b = d[:, 0:1] * oc[:, 0] + d[:, 1:2] * oc[:, 1] + d[:, 2:3] * oc[:, 2]
    disc = b * b - ((oc * oc).sum(axis=1) - radii * radii)
    rows, cols = np.nonzero((disc >= 0.0) & (b > 0.0))
    return rows, np.maximum(b[rows, cols] - np.sqrt(disc[rows, cols]), 0.0)


def cast(rays: UnitRays, occluders: Occluders) -> tuple[np.ndarray, np.ndarray]:
    """(depth [m] per ray, whether the ray ended on an object rather than the table or its
    reach): the first of `occluders` each ray meets. Each group's bounding sphere is met first
    and only the rays that meet it are tried on its spheres."""
    o, d = rays.origin, rays.directions
    depth = np.full(len(d), rays.reach)
    groups = [(a, b) for a, b in occluders.groups or ((0, len(occluders.radii)),) if b > a]
    if groups:
        spheres = [(occluders.centres[a:b], occluders.radii[a:b]) for a, b in groups]
        centre = np.array([(c.min(axis=0) + c.max(axis=0)) / 2 for c, _ in spheres])
        bound = np.array(
            [
                (np.linalg.norm(c - m, axis=1) + r).max()
                for (c, r), m in zip(spheres, centre, strict=True)
            ]
        )
        oc = centre - o
        along = d[:, 0:1] * oc[:, 0] + d[:, 1:2] * oc[:, 1] + d[:, 2:3] * oc[:, 2]
        meets = along * along - ((oc * oc).sum(axis=1) - bound * bound) >= 0.0
        for g in np.flatnonzero(meets.any(axis=0)):
            near = np.flatnonzero(meets[:, g])
            rows, t = _meet(o, d[near], *spheres[g])
            np.minimum.at(depth, near[rows], t)
    hit = depth < rays.reach
    x0, x1, y0, y1 = occluders.table
    with np.errstate(divide="ignore", invalid="ignore"):
        t_top = (occluders.top - o[2]) / d[:, 2]
    on_top = o + t_top[:, None] * d
    table = (
        (t_top > 0)
        & (on_top[:, 0] >= x0)
        & (on_top[:, 0] <= x1)
        & (on_top[:, 1] >= y0)
        & (on_top[:, 1] <= y1)
        & (t_top < depth)
    )
    return np.where(table, t_top, depth), hit & ~table


def view(
    rays: UnitRays, depth: np.ndarray, hit: np.ndarray, grid: VoxelGrid, tolerance: float
) -> tuple[np.ndarray, np.ndarray]:
    """One unit's frame: (the voxels it saw free, a flat boolean over `grid`; the points its
    rays ended on an object, k×3 world). A ray sees free only the points it passed `tolerance`
    [m] short of its depth."""
    free = np.zeros(grid.size, dtype=bool)
    short = rays.sample_t < depth[rays.sample_ray] - tolerance
    free[rays.sample_voxel[short]] = True
    return free, rays.origin + depth[hit, None] * rays.directions[hit]


def cover(shapes, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Spheres that together hold each of `shapes` (`robot_envelope.Primitives`: a box swept by
    a disc, rounded): (body row per sphere, centre in that body's frame (k×3), radius). Each
    shape gets a row of spheres at most `spacing` [m] apart along its longest extent, each
    reaching across the other two (a chain, as the person model's limbs), plus its rounding."""
    bodies, points, radii = [], [], []
    for m in range(len(shapes.names)):
        disc = float(shapes.disc[m])
        extent = shapes.half[m] + np.array([disc, disc, 0.0])
        axis = int(np.argmax(extent))
        count = int(np.ceil(2 * extent[axis] / spacing)) + 1
        steps = np.linspace(-extent[axis], extent[axis], count)
        local = np.zeros((count, 3))
        local[:, axis] = steps
        half_step = extent[axis] / max(count - 1, 1)
        across = float(np.linalg.norm(np.delete(extent, axis)))
        bodies.append(np.full(count, shapes.body[m]))
        points.append(local @ shapes.R_BC[m].T + shapes.p_BC[m])
        radius = float(np.hypot(across, half_step)) + float(shapes.round[m])
        radii.append(np.full(count, radius))
    body = np.concatenate(bodies)
    order = np.argsort(body, kind="stable")  # by body: each body's spheres together
    return body[order], np.concatenate(points)[order], np.concatenate(radii)[order]


def posed(cover_spheres, R_WB: np.ndarray, p_WB: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centres in world, radii) of `cover` spheres on bodies posed (R_WB, p_WB)."""
    body, p_B, radii = cover_spheres
    return np.einsum("kij,kj->ki", R_WB[body], p_B) + p_WB[body], radii


def within(points: np.ndarray, centres: np.ndarray, radii: np.ndarray, margin: float):
    """Whether each of `points` lies within `margin` of any sphere (`centres`, `radii`)."""
    if len(radii) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    d2 = (
        (points * points).sum(axis=1)[:, None]
        + (centres * centres).sum(axis=1)[None, :]
        - 2.0 * points @ centres.T
    )
    return (d2 <= (radii[None, :] + margin) ** 2).any(axis=1)


def dilate(grid: VoxelGrid, mask: np.ndarray, distance: float) -> np.ndarray:
    """The voxels (flat boolean) within `distance` [m] of a voxel of `mask`, along each axis
    (a cube round each: what a person in `mask` could reach)."""
    steps = int(np.ceil(distance / grid.pitch - 1e-6))
    grown = mask.reshape(grid.shape).copy()
    for axis in range(3):
        base = grown.copy()
        for step in range(1, min(steps, grid.shape[axis]) + 1):
            ahead = [slice(None)] * 3
            behind = [slice(None)] * 3
            ahead[axis], behind[axis] = slice(step, None), slice(None, -step)
            grown[tuple(ahead)] |= base[tuple(behind)]
            grown[tuple(behind)] |= base[tuple(ahead)]
    return grown.ravel()


def unexplained(
    grid: VoxelGrid,
    free: np.ndarray,
    points: np.ndarray,
    robot: tuple[np.ndarray, np.ndarray],
    margin: float,
    fixed: np.ndarray,
    reach: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a person may hold: (the flat indices of the voxels within `reach` (a flat boolean:
    where a person could have come) that no unit saw free and no ray met anything in; the
    points rays met, k×3; the flat indices of the voxels those lie in), each explained neither
    by the `robot` (sphere centres and radii covering its shapes, posed from its encoders)
    within `margin` [m] nor by a `fixed` object (a flat boolean). A voxel a ray met something
    in is given by the points met: the surface where it was seen, not the whole voxel."""
    flat = grid.index(points)
    points = points[flat >= 0]
    flat = flat[flat >= 0]
    keep = ~fixed[flat]
    points, flat = points[keep], flat[keep]
    keep = ~within(points, robot[0], robot[1], margin)
    points, flat = points[keep], flat[keep]
    met = np.zeros(grid.size, dtype=bool)
    met[flat] = True
    candidate = np.flatnonzero(~free & ~met & ~fixed & reach)
    robot_held = within(grid.centres(candidate), robot[0], robot[1], margin)
    return candidate[~robot_held], points, np.unique(flat)


def surface(grid: VoxelGrid, flat: np.ndarray) -> np.ndarray:
    """Those of the voxels `flat` with a face open to a voxel not among them (or the grid's
    edge): the volume's surface, nearer any outside point than the voxels inside it."""
    occupied = np.zeros(grid.shape, dtype=bool)
    occupied.flat[flat] = True
    inner = np.zeros_like(occupied)
    inner[1:-1, 1:-1, 1:-1] = True
    for axis in range(3):
        for shift in (1, -1):
            inner &= np.roll(occupied, shift, axis=axis)
    return np.flatnonzero(occupied & ~inner)


def as_body(
    grid: VoxelGrid,
    flat: np.ndarray,
    points: np.ndarray,
    point_radius: float,
    head_above: float,
    stamp: float,
) -> BodySpheres:
    """A body reading of the voxels `flat` (a sphere round each) and the `points` seen (each a
    sphere of `point_radius`, the depth's noise): at rest (the sensor measures no speed; the
    safety function takes ISO 13855's), those whose centre lies above `head_above` [m] in the
    head's group, the others in the torso's, taken at `stamp` [s]."""
    centres = np.vstack([grid.centres(flat), points])
    radii = np.concatenate([np.full(len(flat), grid.radius), np.full(len(points), point_radius)])
    order = np.argsort(centres[:, 2] > head_above, kind="stable")
    centres, radii = centres[order], radii[order]
    low = int(np.count_nonzero(centres[:, 2] <= head_above))
    n = len(centres)
    groups = ((0, 0), (0, 0), (0, 0), (0, low), (low, n))
    return BodySpheres(centres, radii, np.zeros((n, 3)), groups, stamp=stamp)


__all__ = [
    "Occluders",
    "UnitRays",
    "VoxelGrid",
    "as_body",
    "cast",
    "cover",
    "dilate",
    "look_at",
    "posed",
    "surface",
    "unexplained",
    "unit_rays",
    "view",
    "within",
]
