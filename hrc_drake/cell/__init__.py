"""The Drake cell: the diagram built from a scenario, the SlotMonitor, the Supervisor, runs."""

from hrc_drake.cell.builder import (
    CellScenario,
    CellStation,
    build_cell,
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
    "save_meshcat_html",
    "simulate_cell",
]
