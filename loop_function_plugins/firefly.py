"""Firefly figure: the synchrony index, the Kuramoto order parameter of the robots' phases, each
phase read from the ticks since the robot last lit its LEDs."""
from __future__ import annotations

import numpy as np

from composed_sim.loop_functions import LoopFunctions


def synchrony_index(phases: np.ndarray) -> float:
    """|mean of exp(2πi·phase)| over the phases in [0, 1): 1 when all flash together, near 0 when
    spread evenly. NaN for no phase."""
    if len(phases) == 0:
        return float("nan")
    return float(np.abs(np.exp(2j * np.pi * phases).mean()))


class FireflyLoopFunctions(LoopFunctions):
    """``period_ticks``: the controllers' flash period (the world's firefly ``period_ticks``)."""

    def __init__(self, period_ticks: int = 20):
        if not period_ticks >= 1:
            raise ValueError(f"period_ticks must be >= 1 (got {period_ticks})")
        self.period = int(period_ticks)
        self.last_flash: np.ndarray | None = None

    def init(self, world, sim) -> None:
        self.last_flash = np.full(sim.n, -1)

    def post_step(self, sim) -> None:      # every tick, whatever every_ticks: no flash is missed
        self.last_flash[sim.led_colors.any(axis=(1, 2))] = sim.tick

    def metrics(self, sim) -> dict:
        lit = sim.led_colors.any(axis=(1, 2))
        seen = self.last_flash >= 0            # robots that flashed at least once
        phases = ((sim.tick - self.last_flash[seen]) % self.period) / self.period
        return {"synchrony_index": synchrony_index(phases), "flashing": int(lit.sum())}
