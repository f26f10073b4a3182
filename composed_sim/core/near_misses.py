"""Near misses between drones: two drones inside each other's safety ellipsoid.

A pair is close when (d_xy / r)² + (d_z / (k r))² < 1, r the horizontal radius and k the height
ratio (world/flight.py): the ellipsoid test is a ball test in coordinates whose z is divided by k,
so one k-d tree query per tick finds every close pair (scipy's cKDTree, vectorised). A pair where
both drones sit on the floor is not counted (drones parked side by side). An event is one
approach: the tick the pair came close, the two robots, and the closest 3D distance between
their centres until they part (an event still open at the end keeps its closest so far).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass
class NearMiss:
    tick: int             # the first tick the pair was close
    first: int            # robot indices, first < second
    second: int
    distance_m: float     # the closest their centres came while close


class NearMisses:
    def __init__(self, robots: np.ndarray, radius_m: float, height_ratio: float):
        self.robots = np.asarray(robots, dtype=np.int64)     # [d] the drones' robot indices
        self.radius_m, self.height_ratio = radius_m, height_ratio
        self.events: list[NearMiss] = []
        self._open: dict[tuple[int, int], int] = {}          # close pair (robot indices) → its event

    def check(self, tick: int, positions: np.ndarray, altitudes: np.ndarray) -> None:
        """The drones' xy [d, 2] and altitudes [d] after step ``tick``."""
        if len(self.robots) < 2:
            return
        scaled = np.column_stack([positions, altitudes / self.height_ratio])
        pairs = cKDTree(scaled).query_pairs(self.radius_m, output_type="ndarray")
        if len(pairs):
            airborne = altitudes > 0.0
            pairs = pairs[airborne[pairs[:, 0]] | airborne[pairs[:, 1]]]
        xyz = np.column_stack([positions, altitudes])
        distances = np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1)
        robot_pairs = np.sort(self.robots[pairs], axis=1)
        still_open = {}
        for (a, b), d in zip(robot_pairs.tolist(), distances.tolist()):
            index = self._open.get((a, b))
            if index is None:
                index = len(self.events)
                self.events.append(NearMiss(tick, a, b, d))
            elif d < self.events[index].distance_m:
                self.events[index].distance_m = d
            still_open[(a, b)] = index
        self._open = still_open

    def summary(self, names: list[str]) -> dict:
        """For summary.json: how many, the closest, and the pairs."""
        closest = min(self.events, key=lambda e: e.distance_m, default=None)
        return {"count": len(self.events), "radius_m": self.radius_m, "height_ratio": self.height_ratio,
                "closest_m": None if closest is None else round(closest.distance_m, 4),
                "pairs": sorted({f"{names[e.first]}-{names[e.second]}" for e in self.events})}
