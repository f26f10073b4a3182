"""Flocking figures: how far the swarm's centroid is from the light, how close the robots keep,
and how regular the lattice they form is."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.loop_functions import LoopFunctions


def lattice_order(positions: np.ndarray, target_distance_m: float, range_factor: float = 1.8) -> float:
    """1 − the mean relative deviation |d − D| / D of every neighbour pair's distance d from the
    target distance D, over the pairs closer than ``range_factor`` · D (the flocking controller's
    interaction range); 1 is a perfect lattice, 0 or less none. NaN without any such pair."""
    pairs = cKDTree(positions).query_pairs(range_factor * target_distance_m, output_type="ndarray")
    if len(pairs) == 0:
        return float("nan")
    d = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    return float(1.0 - np.mean(np.abs(d - target_distance_m)) / target_distance_m)


def flocking_figures(positions: np.ndarray, light, target_distance_m: float) -> dict:
    """positions [n, 2]; light: (x, y) or None."""
    out: dict = {}
    if len(positions) == 0:
        return out
    centroid = positions.mean(axis=0)
    if light is not None:
        out["centroid_to_light_m"] = float(np.linalg.norm(centroid - np.asarray(light)))
    if len(positions) > 1:
        d, _ = cKDTree(positions).query(positions, k=2)
        out["mean_nearest_neighbour_m"] = float(d[:, 1].mean())
        out["min_pair_distance_m"] = float(d[:, 1].min())
        out["lattice_order"] = lattice_order(positions, target_distance_m)
    return out


class FlockingLoopFunctions(LoopFunctions):
    """Metrics only. ``target_distance_m``: the controller's Lennard-Jones equilibrium distance;
    ``stop_within_m``: end the run once the centroid is this close to the light (None: never)."""

    def __init__(self, target_distance_m: float = 0.75, stop_within_m: float | None = None):
        if not target_distance_m > 0:
            raise ValueError(f"target_distance_m must be > 0 (got {target_distance_m})")
        self.target = float(target_distance_m)
        self.stop_within = stop_within_m
        self.light = None

    def init(self, world, sim) -> None:
        self.light = world.lights[0].position if world.lights else None

    def metrics(self, sim) -> dict:
        return flocking_figures(sim.positions, self.light, self.target)

    def is_finished(self, sim) -> bool:
        if self.stop_within is None or self.light is None:
            return False
        return float(np.linalg.norm(sim.positions.mean(axis=0) - np.asarray(self.light))) <= self.stop_within

    @staticmethod
    def describe(initial: dict, final: dict) -> list[str]:
        lines = []
        if "centroid_to_light_m" in final:
            lines.append(f"  centroid to light: {initial['centroid_to_light_m']:.2f} m → "
                         f"{final['centroid_to_light_m']:.2f} m")
        if "mean_nearest_neighbour_m" in final:
            lines.append(f"  mean nearest-neighbour distance: {final['mean_nearest_neighbour_m']:.3f} m, "
                         f"closest pair {final['min_pair_distance_m']:.3f} m, "
                         f"lattice order {final['lattice_order']:.3f}")
        return lines
