"""Pacing a run to a multiple of real time (``--rate R``), as a tick observer: it sleeps in the
lockstep loop between two ticks, after the other observers have shown the tick."""
from __future__ import annotations

import time
from typing import Optional

from composed_sim.core.simulation import Simulation


class Pacer:
    """A tick observer that holds the run to at most ``rate`` × real time (``--rate``): tick k
    ends no earlier than k · tick_s / rate after tick 0. The schedule is absolute: after a slow
    tick the next ones go unpaced until the run is back on schedule, so the average rate holds."""

    def __init__(self, rate: float, tick_s: float):
        self.period_s = tick_s / rate
        self._start: Optional[float] = None

    def on_tick(self, sim: Simulation) -> None:
        now = time.perf_counter()
        if self._start is None:
            self._start = now - sim.tick * self.period_s
            return
        delay = self._start + sim.tick * self.period_s - now
        if delay > 0:
            time.sleep(delay)
