"""A `Plan` as plain data, exactly: for handing plans between processes.

pydrake's trajectories do not all pickle (PiecewisePolynomial has no pickle support in pydrake
1.51), so a plan is written as the exact parameters of each trajectory piece, as the planner
built them (`Timeline` in `timeline.py`, `Retimed.trajectory()` in `trajectory.py`):

- `PiecewisePolynomial`: the breaks and every segment's polynomial coefficients (local time,
  lowest power first), as `getPolynomial` holds them;
- `BsplineTrajectory`: the basis (order, knots) and the control points;
- `PathParameterizedTrajectory`: its path and its time scaling, each a trajectory;
- `CompositeTrajectory`: its segments as they are stored (`AlignAndConcatenate` wraps each
  segment after the first in a `PathParameterizedTrajectory` with a linear time shift), rebuilt
  with the constructor, so the rebuilt tree is the original tree and evaluates to the same bits.

The plain data holds only dicts, lists, bytes, strings, floats, ints, bools and None (Python
floats round-trip exactly through pickle; polynomial coefficients are packed little-endian
float64 bytes).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
from pydrake.math import BsplineBasis
from pydrake.polynomial import Polynomial
from pydrake.trajectories import (
    BsplineTrajectory,
    CompositeTrajectory,
    PathParameterizedTrajectory,
    PiecewisePolynomial,
    Trajectory,
)

from hrc_drake.motion.plan import CheckPhase, MotionTiming, Plan, Segment, Stage
from hrc_drake.motion.scene import Layout

FORMAT = 1
"""The plain-data format's version; `plan_from_data` refuses any other."""


def trajectory_to_data(trajectory: Trajectory) -> dict:
    """The exact parameters of a trajectory tree (the piece types a plan uses) as plain data.

    TypeError naming the type for any other trajectory type."""
    if isinstance(trajectory, CompositeTrajectory):
        return {
            "type": "CompositeTrajectory",
            "segments": [
                trajectory_to_data(trajectory.segment(i))
                for i in range(trajectory.get_number_of_segments())
            ],
        }
    if isinstance(trajectory, PathParameterizedTrajectory):
        return {
            "type": "PathParameterizedTrajectory",
            "path": trajectory_to_data(trajectory.path()),
            "time_scaling": trajectory_to_data(trajectory.time_scaling()),
        }
    if isinstance(trajectory, PiecewisePolynomial):
        return _piecewise_to_data(trajectory)
    if isinstance(trajectory, BsplineTrajectory):
        basis = trajectory.basis()
        return {
            "type": "BsplineTrajectory",
            "order": int(basis.order()),
            "knots": [float(k) for k in basis.knots()],
            "control_points": [
                np.asarray(c, dtype=float).tolist() for c in trajectory.control_points()
            ],
        }
    raise TypeError(
        f"plan_io cannot write a {type(trajectory).__name__}; it writes CompositeTrajectory, "
        "PathParameterizedTrajectory, PiecewisePolynomial and BsplineTrajectory"
    )


def _piecewise_to_data(pp: PiecewisePolynomial) -> dict:
    rows, cols = pp.rows(), pp.cols()
    # Segment by segment, row by row: each polynomial's coefficients, packed as float64 bytes
    # (the receiver rebuilds them from one buffer, without a Python float per coefficient).
    polynomials = [
        pp.getPolynomial(i, r, c).GetCoefficients()
        for i in range(pp.get_number_of_segments())
        for r in range(rows)
        for c in range(cols)
    ]
    return {
        "type": "PiecewisePolynomial",
        "rows": rows,
        "cols": cols,
        "breaks": [float(t) for t in pp.get_segment_times()],
        "lengths": [len(p) for p in polynomials],
        "coefficients": np.concatenate(polynomials).astype("<f8").tobytes(),
    }


def trajectory_from_data(data: dict) -> Trajectory:
    """The trajectory tree written by `trajectory_to_data`; ValueError on an unknown type."""
    kind = data.get("type")
    if kind == "CompositeTrajectory":
        return CompositeTrajectory([trajectory_from_data(s) for s in data["segments"]])
    if kind == "PathParameterizedTrajectory":
        return PathParameterizedTrajectory(
            trajectory_from_data(data["path"]), trajectory_from_data(data["time_scaling"])
        )
    if kind == "PiecewisePolynomial":
        return _piecewise_from_data(data)
    if kind == "BsplineTrajectory":
        basis = BsplineBasis(data["order"], data["knots"])
        return BsplineTrajectory(basis, [np.array(c, dtype=float) for c in data["control_points"]])
    raise ValueError(f"plan data holds an unknown trajectory type {kind!r}")


def _piecewise_from_data(data: dict) -> PiecewisePolynomial:
    rows, cols, lengths = data["rows"], data["cols"], data["lengths"]
    packed = np.frombuffer(data["coefficients"], dtype="<f8")
    if len(packed) != sum(lengths) or len(lengths) != rows * cols * (len(data["breaks"]) - 1):
        raise ValueError("plan data: a PiecewisePolynomial's coefficients do not match its breaks")
    if len(set(lengths)) == 1:
        coefficients = packed.reshape(len(lengths), lengths[0])
    else:
        ends = np.cumsum(lengths)
        coefficients = [packed[end - n : end] for end, n in zip(ends, lengths, strict=True)]
    polynomials = [Polynomial(c) for c in coefficients]
    if rows == 1 and cols == 1:
        # The scalar constructor: no object matrices to build (time scalings are 1×1).
        return PiecewisePolynomial(polynomials, data["breaks"])
    size = rows * cols
    matrices = [
        np.array(polynomials[k : k + size], dtype=object).reshape(rows, cols)
        for k in range(0, len(polynomials), size)
    ]
    return PiecewisePolynomial(matrices, data["breaks"])


# Plan fields written by their own structure; every other field of a Plan (and every field of
# a MotionTiming) is a plain value (str, float, int, bool or None), copied as it is, so that a
# new scalar field needs no change here.
_STRUCTURED = ("configuration", "trajectory", "gripper", "segments", "phases", "motions")


def _scalars(value_object, skip: tuple[str, ...] = ()) -> dict:
    values = {}
    for field in dataclasses.fields(value_object):
        if field.name in skip:
            continue
        value = getattr(value_object, field.name)
        if isinstance(value, np.generic):
            value = value.item()
        if not (value is None or isinstance(value, str | int | float | bool)):
            raise TypeError(
                f"plan_io writes {type(value_object).__name__}.{field.name} as a plain value, "
                f"not a {type(value).__name__}: give it a structured form in plan_io"
            )
        values[field.name] = value
    return values


def plan_to_data(plan: Plan) -> dict:
    """A plan as plain data (dicts, lists, bytes, str, float, int, bool, None), exact."""
    return {
        "format": FORMAT,
        "scalars": _scalars(plan, skip=_STRUCTURED),
        "configuration": sorted(plan.configuration),
        "trajectory": trajectory_to_data(plan.trajectory),
        "gripper": trajectory_to_data(plan.gripper),
        "segments": [[s.stage.value, float(s.start), float(s.end)] for s in plan.segments],
        "phases": [
            {
                "start": float(p.start),
                "end": float(p.end),
                "placed": [list(pair) for pair in p.layout.placed],
                "carried": p.layout.carried,
                "opening": float(p.layout.opening),
                "loose": [[instance, list(values)] for instance, values in p.layout.loose],
                "allowed_contacts": [list(pair) for pair in p.allowed_contacts],
            }
            for p in plan.phases
        ],
        "motions": [_scalars(m) for m in plan.motions],
    }


def plan_from_data_in_steps(data: dict) -> Iterator[Plan | None]:
    """Rebuilds the plan written by `plan_to_data` a piece at a time: yields None after each
    top-level piece of the arm trajectory (a fraction of a millisecond each), then the Plan.

    A control loop spreads a rebuild over its updates with it. ValueError if the data is of
    another format."""
    if data.get("format") != FORMAT:
        raise ValueError(
            f"plan data of format {data.get('format')!r}; this version reads format {FORMAT}"
        )
    arm = data["trajectory"]
    if arm.get("type") == "CompositeTrajectory":
        pieces = []
        for piece in arm["segments"]:
            pieces.append(trajectory_from_data(piece))
            yield None
        trajectory = CompositeTrajectory(pieces)
    else:
        trajectory = trajectory_from_data(arm)
    gripper = trajectory_from_data(data["gripper"])
    if not isinstance(gripper, PiecewisePolynomial):
        raise ValueError(f"a plan's gripper is a PiecewisePolynomial, not {type(gripper).__name__}")
    yield _plan(data, trajectory, gripper)


def _plan(data: dict, trajectory: Trajectory, gripper: PiecewisePolynomial) -> Plan:
    phases = tuple(
        CheckPhase(
            p["start"],
            p["end"],
            Layout(
                tuple(tuple(pair) for pair in p["placed"]),
                p["carried"],
                p["opening"],
                tuple((instance, tuple(values)) for instance, values in p.get("loose", ())),
            ),
            tuple(tuple(pair) for pair in p["allowed_contacts"]),
        )
        for p in data["phases"]
    )
    return Plan(
        **data["scalars"],
        configuration=frozenset(data["configuration"]),
        trajectory=trajectory,
        gripper=gripper,
        segments=tuple(Segment(Stage(s), start, end) for s, start, end in data["segments"]),
        phases=phases,
        motions=tuple(MotionTiming(**m) for m in data["motions"]),
    )


def plan_from_data(data: dict) -> Plan:
    """The plan written by `plan_to_data`; ValueError if the data is of another format."""
    for result in plan_from_data_in_steps(data):
        if result is not None:
            return result
    raise AssertionError("plan_from_data_in_steps ends with the plan")
