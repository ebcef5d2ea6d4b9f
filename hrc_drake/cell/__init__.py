"""The Drake cell: diagram builder and SlotMonitor."""

from hrc_drake.cell.builder import (
    CellScenario,
    CellStation,
    build_cell,
    load_scenario,
    placement_poses,
    save_meshcat_html,
    simulate_cell,
)
from hrc_drake.cell.slot_monitor import (
    CellConfiguration,
    PartPlacement,
    PartStatus,
    SlotMonitor,
    SlotTolerances,
)

__all__ = [
    "CellConfiguration",
    "CellScenario",
    "CellStation",
    "PartPlacement",
    "PartStatus",
    "SlotMonitor",
    "SlotTolerances",
    "build_cell",
    "load_scenario",
    "placement_poses",
    "save_meshcat_html",
    "simulate_cell",
]
