"""Timing helpers shared by the benchmarks."""

from __future__ import annotations

import time


def best_cpu_rtf(simulator, piece: float, repeats: int, warm_up: float = 0.2) -> float:
    """The best real-time factor in this process's CPU time of `repeats` pieces of `piece`
    simulated seconds, after `warm_up` seconds (caches filled, contacts settled). CPU time, so
    that other work on a shared machine does not count."""
    context = simulator.get_context()
    simulator.AdvanceTo(context.get_time() + warm_up)
    best = 0.0
    for _ in range(repeats):
        cpu = time.process_time()
        simulator.AdvanceTo(context.get_time() + piece)
        best = max(best, piece / (time.process_time() - cpu))
    return best
