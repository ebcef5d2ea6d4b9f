"""Runs of the cell: the closed loop of a scenario (`run`, `loop`), cell evaluations
(`evaluate`), the cost table planned in the cell (`costs`), fault reports and the recording's
view (`run_scenario` is imported here)."""

from hrc_drake.cell.run.run import build_closed_loop, run_scenario

__all__ = ["build_closed_loop", "run_scenario"]
