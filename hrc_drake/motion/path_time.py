"""Time a motion along its path against a forecast of the operator: a path–time search.

Path–velocity decomposition (Kant & Zucker 1986): the plan fixes each motion's path (its plan
time τ ∈ [τ0, τ1] at full speed gives q(τ), q̇(τ)); here only its timing is chosen. The arm runs
the path at a speed scale s = dτ/dt ∈ [0, 1], which may change by at most Δs per step of STEP
seconds, Δs = a STEP / max_j |q̇_j(τ)| with `a` the joint acceleration limit (every joint
speeding up or braking together along the path, as the Supervisor ramps its speed and as the
monitor's stopping arithmetic in `hrc_drake.cell.ssm` assumes). At every step s must be at
most the scale that speed-and-separation monitoring allows against the forecast body at that
moment (`ScaleFn` on `Occupancy`), or the arm brakes as hard as it may (what the monitor makes
it do when it cannot keep to the limit).

`time_path` searches that (τ, s, t) lattice breadth-first in time: s on LEVELS levels, τ in
cells of STEP / LEVELS, so that a step at level j moves exactly j cells. The first step at which
a state reaches τ1 is the earliest arrival; the profile is traced back from it. It may wait at
the start, slow down, stop mid-path and go on. Monitoring alone's timing (`reactive_profile`:
s follows the allowed scale within the ramp) and a wait at the start followed by it are
profiles of the same lattice, so the search's arrival is never later than theirs against the
same forecast (on the lattice; with LEVELS = 20 levels the quantised allowed scale is at most
1/20 below the monitor's own).

`path_time_around` times each motion of a plan that way, one after the other, and keeps a
motion's timing only where it arrives at least PAYS before monitoring alone's own (the
monitor's limit at every step, no reaction window): on a path whose limit depends on the pose
and the time only, going as fast as allowed is nearly the earliest, and a timing that gains
less than a step would only add the following's lag. It returns what the Supervisor
follows: a `Hold` for a wait at a motion's start (a rest point) and a `SpeedCap` for the
speed along it where the timing goes slower than the monitor would allow (elsewhere the
monitor's own limit governs). Monitoring stays underneath and acts on the body as
measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hrc_drake.motion.clearance import Hold, MotionPath, Occupancy, ScaleFn, motion_path
from hrc_drake.motion.plan import Plan

STEP = 0.1  # s per step of the search: the forecast's own sampling (OperatorForecast.SAMPLE)
LEVELS = 20  # speed levels above 0: s ∈ {0, 1/20, ..., 1}
POSE_STEP = 0.1  # s of plan time between the poses the monitor is asked about
# s: a motion's timing is followed only where it arrives at least this much before monitoring
# alone's own timing against the same forecast; elsewhere the monitor alone times it, so that
# a timing that gains nothing costs nothing either (see `path_time_around`).
PAYS = STEP
_EPS = 1e-6
_REST = 1e-6  # rad/s: a path this slow is at rest (the speed may jump there)


@dataclass(frozen=True)
class Profile:
    """A timing of a path: at `times` (every STEP from the start) the plan time `taus` and the
    speed scale `speeds` held over the next step; `arrival`: when the path's end is reached;
    `at_limit`: the steps where the speed is as high as the monitor allows against the forecast
    (no slower by choice)."""

    times: np.ndarray
    taus: np.ndarray
    speeds: np.ndarray
    arrival: float
    at_limit: np.ndarray

    @property
    def wait(self) -> float:
        """Seconds it stands at its start before it moves."""
        moving = np.nonzero(self.speeds > 0)[0]
        return float(moving[0] * STEP) if len(moving) else 0.0


class _Lattice:
    """The (τ, s) lattice of a path from `begin` (absolute [s]), and the allowed speed levels
    on it, asked of the forecast monitor only where the search goes (memoised). With a
    `reaction` time T_r, the level allowed at a step is the least the monitor allows the pose
    over the next T_r + T_s (T_s its stopping time at full speed): the forecast body's travel
    over that window counts, as the run's own check counts the person's (the monitor itself
    knows only their speed now)."""

    def __init__(self, path, begin, occupancy, scale, acceleration, reaction=None, raw=None):
        self.path, self.begin, self.occupancy, self.scale = path, begin, occupancy, scale
        self.acceleration = acceleration
        h = STEP / LEVELS
        self.length = max(1, int(np.ceil((path.taus[-1] - path.taus[0]) / h - _EPS)))
        taus = path.taus[0] + np.arange(self.length + 1) * h
        # Each cell's pose: the nearest sample; its ramp from the faster of the two around it.
        pose = np.clip(np.searchsorted(path.taus, taus), 0, len(path.taus) - 1)
        fast = np.abs(path.qdot).max(axis=1)
        around = np.maximum(fast[pose], fast[np.maximum(pose - 1, 0)])
        with np.errstate(divide="ignore"):
            ramp = np.floor(acceleration * STEP / around * LEVELS + _EPS)
        # At least a level a step, so that no path is frozen at its speed (approximate there).
        self.ramp = np.clip(np.nan_to_num(ramp, posinf=LEVELS), 1, LEVELS).astype(int)
        self.ramp[around <= _REST] = LEVELS
        self.nearest = np.argmin(np.abs(path.taus[:, None] - taus[None, :]), axis=0)
        window = 0.0 if reaction is None else reaction + fast / acceleration
        self.window = np.ceil(np.broadcast_to(window, fast.shape) / STEP - _EPS).astype(int)
        self._allowed: dict[int, np.ndarray] = {}
        # The monitor's own levels, (pose, step) → level; shared with `unwindowed`'s lattice.
        self._raw: dict[tuple[int, int], int] = {} if raw is None else raw

    def unwindowed(self) -> _Lattice:
        """The same lattice with the monitor's own limit at each step (no reaction window),
        asking the monitor nothing this one has asked already."""
        return _Lattice(
            self.path, self.begin, self.occupancy, self.scale, self.acceleration, raw=self._raw
        )

    def tau(self, cell: int) -> float:
        """The plan time of a cell."""
        return float(self.path.taus[0] + cell * STEP / LEVELS)

    def allowed(self, cells: np.ndarray, k: int) -> np.ndarray:
        """The highest speed level allowed at `cells` at step `k` (see the class docstring)."""
        column = self._allowed.get(k)
        if column is None:
            column = np.full(len(self.path.taus), -1, dtype=int)
            self._allowed[k] = column
        poses = self.nearest[cells]
        for p in np.unique(poses[column[poses] < 0]):
            p = int(p)
            column[p] = min(self._level(p, k + d) for d in range(self.window[p] + 1))
        return column[poses]

    def _level(self, p: int, k: int) -> int:
        """The level the monitor allows pose `p` against the forecast body at step `k`."""
        level = self._raw.get((p, k))
        if level is not None:
            return level
        path, occupancy = self.path, self.occupancy
        i = occupancy.at(self.begin + k * STEP)
        level = LEVELS
        if i is not None:  # asked at rest too: the monitor holds an arm a body is too near
            s = self.scale(
                path.q[p],
                path.qdot[p],
                path.opening[p],
                path.carrying[p],
                occupancy.centres[i],
                occupancy.radii,
                occupancy.velocities[i],
            )
            level = int(np.floor(float(np.clip(s, 0.0, 1.0)) * LEVELS + _EPS))
        self._raw[(p, k)] = level
        return level

    def admissible(self, cells: np.ndarray, before: int, k: int, late: bool) -> np.ndarray:
        """(len(cells), LEVELS + 1): the levels the arm may take at `cells` at step `k` coming
        at level `before`: within the ramp, and allowed by the monitor or braking as hard as it
        may. `late`: past the longest wait, the arm at its start goes as soon as it may."""
        ramp = self.ramp[cells][:, None]
        lo = np.maximum(0, before - ramp)
        hi = np.minimum(LEVELS, before + ramp)
        cap = self.allowed(cells, k)[:, None]
        j = np.arange(LEVELS + 1)[None, :]
        ok = (j >= lo) & (j <= hi) & ((j <= cap) | (j == lo))
        if late:
            start = cells == 0
            ok[start, 0] = cap[start, 0] == 0
        return ok


def _arrivals(lattice: _Lattice, states: np.ndarray) -> tuple[int, int, float] | None:
    """(cell, level, fraction of the step) of the state that reaches the end soonest within
    its step, None if none does."""
    best = None
    for j in range(1, LEVELS + 1):
        cells = np.nonzero(states[:, j])[0]
        cells = cells[cells + j >= lattice.length]
        if len(cells):
            cell = int(cells.max())
            fraction = (lattice.length - cell) / j
            if best is None or fraction < best[2]:
                best = (cell, j, fraction)
    return best


def _step(lattice: _Lattice, states: np.ndarray, k: int, late: bool) -> np.ndarray:
    """The states at step k + 1 from those at step k."""
    n = lattice.length
    nxt = np.zeros_like(states)
    for j in range(LEVELS + 1):
        cells = np.nonzero(states[:, j])[0] + j
        cells = cells[cells < n]
        if len(cells):
            nxt[cells] |= lattice.admissible(cells, j, k + 1, late)
    return nxt


def time_path(
    path: MotionPath,
    begin: float,
    occupancy: Occupancy,
    scale: ScaleFn,
    acceleration: float,
    speed: float = 0.0,
    longest: float = np.inf,
    reaction: float | None = None,
) -> Profile | None:
    """The earliest timing of `path` from `begin` (absolute [s]), the arm at its start at speed
    scale `speed`, against the forecast `occupancy` (see the module docstring). It waits at
    its start at most `longest` seconds unless the monitor holds it there; `reaction`: T_r for
    the window over which the body's forecast travel counts (`_Lattice`; None: the monitor's
    own limit at each step). None if it cannot
    arrive within the forecast and the time to run the path after it (it always can: past the
    forecast nothing limits it)."""
    lattice = _Lattice(path, begin, occupancy, scale, acceleration, reaction)
    return _search(lattice, speed, longest)


def _search(lattice: _Lattice, speed: float, longest: float) -> Profile | None:
    """`time_path` on a lattice built already."""
    path, occupancy, begin = lattice.path, lattice.occupancy, lattice.begin
    end = occupancy.times[-1] if len(occupancy.times) else begin
    steps = int(np.ceil((max(end - begin, 0.0) + path.taus[-1] - path.taus[0]) / STEP))
    steps += 2 * LEVELS + 2
    before = int(np.floor(np.clip(speed, 0.0, 1.0) * LEVELS + _EPS))
    first = np.zeros((lattice.length, LEVELS + 1), dtype=bool)
    first[0] = lattice.admissible(np.array([0]), before, 0, longest < 0)[0]
    reached = [first]
    for k in range(steps):
        found = _arrivals(lattice, reached[-1])
        if found is not None:
            return _traced(lattice, reached, found, longest, before)
        reached.append(_step(lattice, reached[-1], k, (k + 1) * STEP > longest + _EPS))
    return None


def _traced(
    lattice: _Lattice, reached: list, found: tuple, longest: float, start_level: int
) -> Profile:
    """The profile that ends in `found` at the last of `reached`, traced back step by step
    (the arm at `start_level` before its first step)."""
    cell, level, fraction = found
    cells, levels = [cell], [level]
    for k in range(len(reached) - 1, 0, -1):
        # Of equal timings, the one that stays back longest (the fastest predecessor, the
        # farthest back): it waits at the motion's start, away from the body, rather than on
        # its way, wherever that is as soon.
        for before in range(LEVELS, -1, -1):
            prev = cell - before
            late = k * STEP > longest + _EPS
            if (
                prev >= 0
                and reached[k - 1][prev, before]
                and lattice.admissible(np.array([cell]), before, k, late)[0, level]
            ):
                cell, level = prev, before
                break
        cells.append(cell)
        levels.append(level)
    return _profile(lattice, cells[::-1], levels[::-1], fraction, start_level)


def _profile(
    lattice: _Lattice, cells: list[int], levels: list[int], fraction: float, start_level: int
) -> Profile:
    """The profile through lattice `cells` at speed `levels`, one a step from the start (the
    arm at `start_level` before it), reaching the end `fraction` of a step after the last."""
    times = lattice.begin + np.arange(len(cells)) * STEP
    taus = np.array([lattice.tau(c) for c in cells])
    # At the limit: as fast as the monitor allows, or as the ramp lets it speed up to that.
    before = [start_level, *levels[:-1]]
    at_limit = np.array(
        [
            level >= min(lattice.allowed(np.array([cell]), k)[0], prev + lattice.ramp[cell])
            for k, (cell, level, prev) in enumerate(zip(cells, levels, before, strict=True))
        ]
    )
    speeds = np.array(levels, dtype=float) / LEVELS
    return Profile(times, taus, speeds, float(times[-1] + fraction * STEP), at_limit)


def reactive_profile(
    path: MotionPath,
    begin: float,
    occupancy: Occupancy,
    scale: ScaleFn,
    acceleration: float,
    speed: float = 0.0,
    wait: float = 0.0,
    reaction: float | None = None,
) -> Profile:
    """Monitoring alone's timing of `path` on the same lattice (the same `reaction`), after a
    `wait` at its start: each step the speed goes toward the level allowed, within the ramp."""
    lattice = _Lattice(path, begin, occupancy, scale, acceleration, reaction)
    return _reactive(lattice, speed, wait)


def _reactive(lattice: _Lattice, speed: float, wait: float = 0.0) -> Profile:
    """`reactive_profile` on a lattice built already."""
    level = start_level = int(np.floor(np.clip(speed, 0.0, 1.0) * LEVELS + _EPS))
    cell, k = 0, 0
    cells, levels = [], []
    while True:  # ends: past the forecast the monitor allows full speed
        ramp = int(lattice.ramp[cell])
        cap = 0 if k * STEP < wait - _EPS else int(lattice.allowed(np.array([cell]), k)[0])
        level = int(np.clip(cap, max(0, level - ramp), min(LEVELS, level + ramp)))
        cells.append(cell)
        levels.append(level)
        if cell + level >= lattice.length:
            fraction = (lattice.length - cell) / level
            break
        cell, k = cell + level, k + 1
    return _profile(lattice, cells, levels, fraction, start_level)


@dataclass(frozen=True)
class SpeedCap:
    """The speed scale the arm keeps under along a motion's plan times [tau0, tau1): from
    `start` [s], `speeds[k]` over the k-th STEP, where it was timed to be at plan time
    `taus[k]`; past them, none."""

    tau0: float
    tau1: float
    start: float
    speeds: tuple[float, ...]
    taus: tuple[float, ...]

    def at(self, now: float) -> float:
        """The cap at `now`: the lower of this step's speed and the next one's, so that the
        arm brakes within the step before a lower speed, never after it (1 past the end)."""
        k = max(0, int(np.floor((now - self.start) / STEP + _EPS)))
        if k >= len(self.speeds):
            return 1.0
        return min(self.speeds[k], self.speeds[k + 1] if k + 1 < len(self.speeds) else 1.0)

    def tau_at(self, now: float) -> float | None:
        """Where the timing has the arm at `now` (None outside the timed steps)."""
        times = self.start + STEP * np.arange(len(self.taus))
        if len(times) < 2 or not times[0] <= now <= times[-1]:
            return None
        return float(np.interp(now, times, self.taus))


def speed_cap(caps: tuple[SpeedCap, ...], now: float, tau: float) -> float:
    """The cap of the timed motion the arm is on at plan time `tau` (1 on none)."""
    for cap in caps:
        if cap.tau0 - _EPS <= tau < cap.tau1:
            return cap.at(now)
    return 1.0


def slip(caps: tuple[SpeedCap, ...], now: float, tau: float) -> float:
    """How far [s of plan time] the arm at `tau` is from where its timing has it at `now`
    (0 off the timed motions)."""
    for cap in caps:
        if cap.tau0 - _EPS <= tau < cap.tau1:
            timed = cap.tau_at(now)
            return 0.0 if timed is None else abs(tau - timed)
    return 0.0


@dataclass(frozen=True)
class PathTiming:
    """What the Supervisor follows: the waits at motions' starts and the speed along them."""

    holds: tuple[Hold, ...] = ()
    caps: tuple[SpeedCap, ...] = ()


def path_time_around(
    plan: Plan,
    tau: float,
    now: float,
    speed: float,
    occupancy: Occupancy,
    scale: ScaleFn,
    max_wait: float,
    acceleration: float,
    end_tau: float | None = None,
    spent: tuple[float, float] | None = None,
    reaction: float | None = None,
) -> PathTiming:
    """The motions of `plan` from plan time `tau` (the arm there at `now`, at speed scale
    `speed`) to `end_tau` (None: the plan's end), each timed by `time_path` after the one
    before as timed; the still parts between them at full speed. A motion under way is timed
    from where the arm is; one to come may wait at its start at most `max_wait` in all
    (`spent`: (plan time, seconds) waited there already); `reaction`: as `time_path`'s. A
    motion the forecast does not reach is left to the monitor, and so is one whose timing
    arrives less than PAYS before monitoring alone's own (the monitor's limit at every step,
    on the same lattice)."""
    end_tau = plan.duration if end_tau is None else end_tau
    holds: list[Hold] = []
    caps: list[SpeedCap] = []
    t, at = now, tau  # the arm at plan time `at` at `t`, as timed so far
    for motion in plan.motions:
        stop = motion.start + motion.duration
        if stop <= tau + _EPS or motion.start >= end_tau - _EPS:
            continue
        start = max(motion.start, tau)
        begin = t + (start - at)
        t, at = begin + (stop - start), stop  # as planned, unless timed below
        if not occupancy.overlaps(begin, begin + (stop - start) + max_wait):
            continue
        under_way = start > motion.start + _EPS
        longest = max_wait
        if spent is not None and abs(spent[0] - motion.start) < _EPS:
            longest = max(0.0, max_wait - spent[1])
        path = motion_path(plan, start, stop, POSE_STEP)
        lattice = _Lattice(path, begin, occupancy, scale, acceleration, reaction)
        setting_off = speed if under_way else 0.0
        profile = _search(lattice, setting_off, np.inf if under_way else longest)
        alone = _reactive(lattice.unwindowed(), setting_off)
        if profile is None or profile.arrival > alone.arrival - PAYS:
            t = alone.arrival  # left to the monitor: its own timing is as soon
            continue
        wait = 0.0 if under_way else profile.wait
        if wait > 0.0:
            holds.append(Hold(motion.start, begin + wait))
        cap = _chosen_cap(profile, start, stop, begin, wait)
        caps += [cap] if cap is not None else []
        t = profile.arrival
    return PathTiming(tuple(holds), tuple(caps))


def _chosen_cap(
    profile: Profile, tau0: float, tau1: float, begin: float, wait: float
) -> SpeedCap | None:
    """The cap of a motion over plan times [tau0, tau1) timed by `profile` from `begin`, after
    its `wait` there: its speed where it goes slower by choice; None if it never does. Where the
    timing goes as fast as the monitor allows, the monitor alone sets the speed: a cap there
    only adds the lattice's 1/LEVELS quantisation and its step's lag to the monitor's own limit
    (on lean shared-desk runs with separation alone, capped everywhere, the assembly took
    x1.29 of monitoring alone's time)."""
    first = round(wait / STEP)
    speeds = np.where(profile.at_limit, 1.0, profile.speeds)[first:]
    if not len(speeds) or speeds.min() >= 1.0 - _EPS:
        return None
    taus = tuple(float(x) for x in profile.taus[first:])
    return SpeedCap(tau0, tau1, begin + wait, tuple(map(float, speeds)), taus)


__all__ = [
    "LEVELS",
    "POSE_STEP",
    "STEP",
    "PathTiming",
    "Profile",
    "SpeedCap",
    "path_time_around",
    "reactive_profile",
    "slip",
    "speed_cap",
    "time_path",
]
