"""Where the cell puts things: the small layout that, with an assembly spec, defines the cell.

The plate (its slot count comes from the spec), the tray and the parts are generated from the
spec; what is left to choose is where the plate and the tray stand and how far apart the slots
are. The defaults fit the UR3 on the table origin; a spec may override them in its `cell:`
section, and a scenario in its own `cell:` section (the scenario wins).

Drake-free, so the task layer and scenario files can carry it.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from hrc_drake.typed_yaml import load_typed

BIN_SIZE = [0.12, 0.09, 0.045]  # a small parts bin on the desk [m] (our choice)
# The robot's base on the table: r 0.064 m and a cable connector 36 mm out
# (shared/reference/ur3-rg2.md).
ROBOT_FOOTPRINT = 0.10


@dataclass
class BinLayout:
    """A bin of hardware on the desk, for the operator (the robot never reaches into it).

    Attributes:
        name: the bin's name (drawn in the scene as `bin_<name>`).
        holds: `bolts` or `nuts`.
        position: [x, y] of its centre on the table, in world [m].
        size: [length along x, width along y, height] [m].
    """

    name: str = ""
    holds: str = "bolts"
    position: list[float] = field(default_factory=lambda: [0.5, -0.3])
    size: list[float] = field(default_factory=lambda: list(BIN_SIZE))

    def grab_point(self) -> tuple[float, float, float]:
        """Where a hand grabbing from the bin has its centre [m]."""
        from hrc_drake.hri.activity import GRAB_ABOVE

        return (self.position[0], self.position[1], GRAB_ABOVE)


@dataclass
class CellLayout:
    """The cell's layout (metres, degrees); see the module docstring.

    Attributes:
        plate_position: the plate's underside centre in world (the UR3 base is at the origin,
            +x in front of it).
        plate_yaw_deg: the plate's turn about world z; at 90 its slot 1 → slot N direction is
            world +y.
        slot_pitch: distance between neighbouring slots.
        tray_position: the tray's underside centre in world; left out, the tray stands beside
            slot 1, `tray_gap` from the plate's end, its centre `tray_offset` from the plate's
            centre line toward the robot (the paper's cell: at [0.20, -0.25, 0]).
        tray_gap: see `tray_position`.
        tray_offset: see `tray_position`.
        tray_yaw_deg: the tray's turn about world z, relative to the plate's (-90 puts the
            tray's long side along the plate).
        part_models: spec part symbol → an SDF file (`package://` URI or path) that follows the
            part conventions of docs/conventions.md; parts not named here are generated.
        bins: the operator's bins of bolts and nuts on the desk (none by default: the
            operator of the Table 2 rows keeps them out of the shared space).
    """

    plate_position: list[float] = field(default_factory=lambda: [0.30, 0.0, 0.0])
    plate_yaw_deg: float = 90.0
    slot_pitch: float = 0.080
    tray_position: list[float] | None = None
    tray_gap: float = 0.015
    tray_offset: float = 0.10
    tray_yaw_deg: float = -90.0
    part_models: dict[str, str] = field(default_factory=dict)
    bins: list[BinLayout] = field(default_factory=list)

    def key(self) -> tuple:
        """A hashable value of the layout the robot's plans depend on (caches, hashes): all of
        it but the bins, which are the operator's and no part of the robot's plant."""
        return (
            tuple(round(x, 9) for x in self.plate_position),
            round(self.plate_yaw_deg, 9),
            round(self.slot_pitch, 9),
            None if self.tray_position is None else tuple(round(x, 9) for x in self.tray_position),
            round(self.tray_gap, 9),
            round(self.tray_offset, 9),
            round(self.tray_yaw_deg, 9),
            tuple(sorted(self.part_models.items())),
        )

    def check(self, where: str = "cell") -> None:
        """ValueError naming the field if a value cannot be a layout."""
        for name in ("plate_position", "tray_position"):
            if getattr(self, name) is not None and len(getattr(self, name)) != 3:
                raise ValueError(f"{where}.{name}: give three coordinates [x, y, z] in metres")
        self._check_bins(where)
        if not 0.05 <= self.slot_pitch <= 0.3:
            raise ValueError(
                f"{where}.slot_pitch: {self.slot_pitch} m is outside 0.05..0.3 m; parts are "
                "7 cm wide, so neighbouring slots closer than 5 cm would overlap"
            )

    def _check_bins(self, where: str) -> None:
        from hrc_drake.hri.activity import BIN_HOLDS

        names = set()
        for i, b in enumerate(self.bins):
            key = f"{where}.bins[{i}]"
            if not b.name or b.name in names:
                raise ValueError(f"{key}.name: give each bin its own name, got {b.name!r}")
            names.add(b.name)
            if b.holds not in BIN_HOLDS:
                raise ValueError(f"{key}.holds: {b.holds!r} is not one of {list(BIN_HOLDS)}")
            if len(b.position) != 2 or len(b.size) != 3 or min(b.size) <= 0:
                raise ValueError(
                    f"{key}: give position [x, y] and size [length, width, height] in metres, "
                    "sizes positive"
                )
            dx = max(abs(b.position[0]) - b.size[0] / 2, 0.0)
            dy = max(abs(b.position[1]) - b.size[1] / 2, 0.0)
            if math.hypot(dx, dy) < ROBOT_FOOTPRINT:
                raise ValueError(
                    f"{key}.position: the bin at {b.position} stands inside the robot's "
                    f"footprint ({ROBOT_FOOTPRINT} m around its base at the origin); move it"
                )


def layout_from(spec_cell: Any, override: CellLayout | None = None) -> CellLayout:
    """The layout of a spec's `cell:` section (parsed YAML, may be None), then `override`."""
    layout = load_typed(CellLayout, data=spec_cell or {})
    if override is not None:
        layout = dataclasses.replace(override)
    layout.check()
    return layout
