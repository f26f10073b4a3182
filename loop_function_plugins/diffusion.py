"""Diffusion figure: the area coverage, the fraction of the arena's cells that a robot has been
in so far."""
from __future__ import annotations

import math

import numpy as np

from composed_sim.loop_functions import LoopFunctions


class DiffusionLoopFunctions(LoopFunctions):
    """``cell_m``: side of the square cells the arena (inside its walls) is cut into."""

    def __init__(self, cell_m: float = 0.25):
        if not cell_m > 0:
            raise ValueError(f"cell_m must be > 0 (got {cell_m})")
        self.cell_m = float(cell_m)

    def init(self, world, sim) -> None:
        bounds = world.arena.inner_bounds()
        if bounds is None:
            raise ValueError("diffusion loop functions: the arena needs a size (arena.size)")
        self.x0, self.y0, x1, y1 = bounds
        self.shape = (math.ceil((x1 - self.x0) / self.cell_m), math.ceil((y1 - self.y0) / self.cell_m))
        self.visited = np.zeros(self.shape, dtype=bool)

    def metrics(self, sim) -> dict:
        ix = np.clip(((sim.positions[:, 0] - self.x0) / self.cell_m).astype(int), 0, self.shape[0] - 1)
        iy = np.clip(((sim.positions[:, 1] - self.y0) / self.cell_m).astype(int), 0, self.shape[1] - 1)
        self.visited[ix, iy] = True
        return {"area_coverage": float(self.visited.mean())}
