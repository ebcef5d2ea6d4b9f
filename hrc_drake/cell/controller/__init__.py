"""The controller: what a real cell would run against the station's ports (see
`hrc_drake.cell.controller.build`, whose entry points are imported here). It imports nothing
from the simulated station."""

from hrc_drake.cell.controller.build import Controller, connect_controller, make_controller

__all__ = ["Controller", "connect_controller", "make_controller"]
