"""Where the cell puts things: the small layout that, with an assembly spec, defines the cell.

The plate (its slot count comes from the spec), the tray and the parts are generated from the
spec; what is left to choose is where the plate and the tray stand and how far apart the slots
are. The defaults fit the UR3 on the table origin; a spec may override them in its `cell:`
section, and a scenario in its own `cell:` section (the scenario wins).

Drake-free, so the task layer and scenario files can carry it.
"""

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from hrc_drake.typed_yaml import load_typed


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
    """

    plate_position: list[float] = field(default_factory=lambda: [0.30, 0.0, 0.0])
    plate_yaw_deg: float = 90.0
    slot_pitch: float = 0.080
    tray_position: list[float] | None = None
    tray_gap: float = 0.015
    tray_offset: float = 0.10
    tray_yaw_deg: float = -90.0
    part_models: dict[str, str] = field(default_factory=dict)

    def key(self) -> tuple:
        """A hashable value of the whole layout (caches, hashes)."""
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
        if not 0.05 <= self.slot_pitch <= 0.3:
            raise ValueError(
                f"{where}.slot_pitch: {self.slot_pitch} m is outside 0.05..0.3 m; parts are "
                "7 cm wide, so neighbouring slots closer than 5 cm would overlap"
            )


def layout_from(spec_cell: Any, override: CellLayout | None = None) -> CellLayout:
    """The layout of a spec's `cell:` section (parsed YAML, may be None), then `override`."""
    layout = load_typed(CellLayout, data=spec_cell or {})
    if override is not None:
        layout = dataclasses.replace(override)
    layout.check()
    return layout
