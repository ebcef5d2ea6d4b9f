"""The simulated station: the cell's plant and everything the simulator plays (see
`hrc_drake.cell.station.build`, whose entry points are imported here)."""

from hrc_drake.cell.station.build import make_cell_station, simulate_station, station_scenario
from hrc_drake.cell.station.cell_station import CellStation

__all__ = ["CellStation", "make_cell_station", "simulate_station", "station_scenario"]
