"""Aggregation figures: the largest cluster of robots, and the fraction of the swarm on the dark
patch."""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from composed_sim.devices.common.floor import Floor
from composed_sim.loop_functions import LoopFunctions


def largest_cluster(positions: np.ndarray, link_m: float) -> int:
    """Robots in the largest group whose members are chained by gaps (centre to centre) under ``link_m``."""
    n = len(positions)
    if n == 0:
        return 0
    pairs = cKDTree(positions).query_pairs(link_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return int(np.bincount(labels).max())


class AggregationLoopFunctions(LoopFunctions):
    """``link_m``: robots closer than this (centre to centre) are in one cluster; ``dark_below``:
    a robot whose centre is over floor greyer than this is on the patch."""

    def __init__(self, link_m: float = 0.1, dark_below: float = 0.5):
        self.link_m, self.dark_below = float(link_m), float(dark_below)
        self.floor: Floor | None = None

    def init(self, world, sim) -> None:
        self.floor = sim.floor if sim.floor is not None else Floor.from_world(world.floor)

    def metrics(self, sim) -> dict:
        on_patch = self.floor.grey(sim.positions) < self.dark_below
        return {"largest_cluster": largest_cluster(sim.positions, self.link_m),
                "fraction_on_patch": float(on_patch.mean()) if sim.n else 0.0}
