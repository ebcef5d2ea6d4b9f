"""The Drake cell: the station built from a scenario, its controller, and closed-loop runs."""

from hrc_drake.cell.ports import CellConfiguration, PartPlacement, PartStatus
from hrc_drake.cell.slot_monitor import SlotMonitor, SlotTolerances
from hrc_drake.cell.station import (
    CellStation,
    make_cell_station,
    simulate_station,
    station_scenario,
)

__all__ = [
    "CellConfiguration",
    "CellStation",
    "PartPlacement",
    "PartStatus",
    "SlotMonitor",
    "SlotTolerances",
    "make_cell_station",
    "simulate_station",
    "station_scenario",
]
