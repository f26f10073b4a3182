"""Behaviour metrics of a run, computed the same way from ARGoS's logged positions and from ours.

positions [K, n, 2] at ticks 0, 10, 20, … (``coarse_ticks``); a metric at tick t:
  light_distance   the swarm's centroid to the light (flocking), or to the arena's centre (m)
  nearest_neighbour  mean distance from each robot to its nearest other robot (m)
  spread           root mean square distance of the robots to their centroid (m)
  speed            mean over robots of the distance covered from t - 10 to t, per second (m/s)
  near_wall        fraction of robots whose body is within 5 cm of a wall of the 4 m pen
  stopped          fraction of robots that covered less than 5 mm from t - 10 to t
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

TICKS = (100, 300, 600)
METRICS = ("light_distance", "nearest_neighbour", "spread", "speed", "near_wall", "stopped")
PEN_HALF_INNER_M = 2.0 - 0.05        # the walls' inner faces (tools/fidelity/experiments)


def metrics_at(positions: np.ndarray, coarse_ticks: np.ndarray, tick: int, *, radius: float,
               target=(0.0, 0.0), tick_s: float = 0.1, pen: bool = True) -> dict[str, float]:
    k = int(np.flatnonzero(coarse_ticks == tick)[0])
    now, before = positions[k], positions[k - 1]
    dt = (coarse_ticks[k] - coarse_ticks[k - 1]) * tick_s
    centroid = now.mean(axis=0)
    d, _ = cKDTree(now).query(now, k=2)
    moved = np.linalg.norm(now - before, axis=1)
    gap = PEN_HALF_INNER_M - np.abs(now).max(axis=1) - radius
    return {"light_distance": float(np.linalg.norm(centroid - np.asarray(target))),
            "nearest_neighbour": float(d[:, 1].mean()),
            "spread": float(np.sqrt(((now - centroid) ** 2).sum(axis=1).mean())),
            "speed": float(moved.mean() / dt),
            "near_wall": float((gap < 0.05).mean()) if pen else 0.0,
            "stopped": float((moved < 0.005).mean())}


def gap(ours: np.ndarray, theirs: np.ndarray) -> float:
    """|mean ours − mean theirs| in pooled standard deviations (0 when both are constant)."""
    pooled = np.sqrt((np.var(ours, ddof=1) + np.var(theirs, ddof=1)) / 2.0)
    diff = abs(float(np.mean(ours) - np.mean(theirs)))
    if pooled == 0.0:
        return 0.0 if diff == 0.0 else float("inf")
    return diff / pooled
