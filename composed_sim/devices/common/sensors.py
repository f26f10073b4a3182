"""What the sensors of devices/ (and the range-and-bearing medium) share: checks of the
per-robot arrays, noise, candidate pairs, and occlusion by robots.

Occlusion follows ARGoS 3's ``dynamics2d_engine.cpp`` (see docs/architecture.md): bodies are
footprints extruded from the floor to their height. ARGoS tests only the point where a ray first
meets a footprint; here any point of the crossing below the height blocks, which differs only for
a descending ray that enters through a body's top (camera → a low LED). Units are SI; ARGoS's
camera cm are metres here.

Robot–robot work is done on candidate pairs from a ``scipy.spatial.cKDTree`` of the robot
centres (pass ``tree=`` to share one tree between the sensors of a tick), so the cost follows
the number of nearby pairs, not n².
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Optional

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common.geometry import segments_blocked_by_cylinders

# Occlusion search: sample spacing along a segment, in robot radii (see blocked_by_robots).
_SPACING_RADII = 4.0
# The walk's rounds: 8 samples a segment, then 4 times as many each round. Each round costs a
# tree and a dozen numpy calls whatever its size, and a worker's block walks its own rays, so
# short rounds cost every worker again (docs/speed.md, "What a worker pays for the whole swarm");
# 1, 2, 4, … took 1.24× the sensing of 8, 32, … at 1280 robots in 8 blocks. Which robots block
# a segment does not depend on the rounds.
_FIRST_ROUND, _ROUND_GROWTH = 8, 4


def _observer_rows(observers, n: int):
    """observers [m] robot indices or None (all) → (observers [m], row of each robot [n], -1 if none)."""
    if observers is None:
        return None, None
    observers = np.asarray(observers, dtype=np.intp)
    row_of = np.full(n, -1, dtype=np.intp)
    row_of[observers] = np.arange(len(observers))
    return observers, row_of


def _robots(positions, headings, radii, heights) -> tuple[np.ndarray, ...]:
    """Check and convert the per-robot arrays: positions [n, 2], headings/radii/heights [n]."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 2:
        raise ValueError(f"positions must have shape (n, 2), got {positions.shape}")
    n = len(positions)
    out = [positions]
    for name, a in (("headings", headings), ("radii", radii), ("heights", heights)):
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
        out.append(a)
    return tuple(out)


def _check_noise(name: str, level: float, rng: Optional[np.random.Generator]) -> None:
    if not level >= 0.0:
        raise ValueError(f"{name} must be >= 0, got {level}")
    if level > 0.0 and rng is None:
        raise ValueError(f"{name}={level} needs a random generator (rng=)")


def _uniform_noise(readings: np.ndarray, level: float, rng) -> np.ndarray:
    """ARGoS: add uniform(-level, level) to every reading, then clamp to [0, 1]."""
    if level > 0.0:
        readings = readings + rng.uniform(-level, level, readings.shape)
    return np.clip(readings, 0.0, 1.0)


def kd_tree(points: np.ndarray, **options) -> "cKDTree":
    """A k-d tree of the points (``scipy.spatial.cKDTree``). scipy is imported on first use: a
    controller process, which only decodes and encodes messages, never loads it (about 10 MB
    less of each process's own memory in multi-process mode)."""
    from scipy.spatial import cKDTree
    return cKDTree(points, **options)


def near_pairs(tree: cKDTree, positions: np.ndarray, radius: float, observers: Optional[np.ndarray] = None,
               p: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs (a, b), a ≠ b, of robots within ``radius`` (Minkowski ``p``) of each other,
    a among ``observers`` (None: all robots). For a few observers (a worker's block) only their
    neighbourhoods are searched, not every pair of the world."""
    if observers is None:
        return _both_ways(tree.query_pairs(radius, p=p, output_type="ndarray"))
    found = kd_tree(positions[observers]).sparse_distance_matrix(tree, radius, p=p, output_type="ndarray")
    a, b = observers[found["i"]].astype(np.intp), found["j"].astype(np.intp)
    keep = a != b
    return a[keep], b[keep]


def _both_ways(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[p, 2] unordered pairs → (a, b) [2p] each, every pair in both orders."""
    return (np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(np.intp),
            np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(np.intp))


def _pair_order(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """The permutation sorting pairs by (a, b), indices < n."""
    if n <= np.iinfo(np.uint16).max:
        # Two stable passes of numpy's radix sort (used for 16-bit keys): O(m), many times faster
        # than a comparison sort of a combined int64 key.
        by_b = np.argsort(b.astype(np.uint16), kind="stable")
        return by_b[np.argsort(a[by_b].astype(np.uint16), kind="stable")]
    return np.argsort(a * n + b)


def _ranges(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand counts [m] into (row [sum], index within the row [sum])."""
    rows = np.repeat(np.arange(len(counts)), counts)
    within = np.arange(len(rows)) - np.repeat(np.cumsum(counts) - counts, counts)
    return rows, within


def blocked_by_robots(p0: np.ndarray, p1: np.ndarray, skip_a: np.ndarray, skip_b: np.ndarray,
                      positions: np.ndarray, radii: np.ndarray, heights: np.ndarray,
                      tree: cKDTree) -> np.ndarray:
    """p0 [m, 3], p1 [m, 3]; skip_a, skip_b [m] robots to ignore per segment (-1: none);
    positions [n, 2], radii [n], heights [n] of the robots, tree over positions → bool [m]:
    the segment passes through a robot body (a cylinder from the floor to its height).

    Only the stretch of a segment lower than the tallest robot can be blocked. Candidates are
    the robots near points sampled along that stretch, walked from p0 in rounds of 8, 32, 128, ...
    samples; a segment leaves the walk at the round of its first blocker. In a dense swarm most long rays
    are blocked within a metre or two, so the work follows that, not the rays' length.
    """
    blocked = np.zeros(len(p0), dtype=bool)
    if len(p0) == 0 or len(positions) == 0:
        return blocked
    h_max, r_max = heights.max(), radii.max()
    if r_max <= 0.0:
        return blocked
    z0, z1 = p0[:, 2], p1[:, 2]
    low0, low1 = z0 < h_max, z1 < h_max
    todo = np.flatnonzero(low0 | low1)
    if len(todo) == 0:
        return blocked
    q0, q1 = p0.take(todo, axis=0), p1.take(todo, axis=0)   # take: many times faster than q[idx] on [m, k]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cross = (h_max - q0[:, 2]) / (q1[:, 2] - q0[:, 2])
    d = q1[:, :2] - q0[:, :2]
    a = q0[:, :2] + np.where(low0[todo], 0.0, t_cross)[:, None] * d
    ab = q0[:, :2] + np.where(low1[todo], 1.0, t_cross)[:, None] * d - a
    # a-b is cut into n pieces no longer than `spacing`, sampled at their midpoints: a body of
    # radius <= r_max touching a-b has its centre within r_max + spacing/2 of a sample.
    # 2 r_max would minimise candidates, but tree work per sample costs more than the exact
    # tests of the extra candidates of a wider ball: 4 r_max was fastest, both for light rays
    # and for camera rays to ring LEDs, in swarms at 5 robots/m² (2, 4, 6, 10 tried).
    spacing = _SPACING_RADII * r_max
    radius = r_max + spacing / 2.0
    n_samples = np.maximum(1, np.ceil(np.sqrt(ab[:, 0] ** 2 + ab[:, 1] ** 2) / spacing)).astype(np.intp)
    active = np.arange(len(todo))
    start, count = 0, _FIRST_ROUND
    while len(active):
        rows, within = _ranges(np.minimum(count, n_samples[active] - start))
        rows = active[rows]
        frac = (start + within + 0.5) / n_samples[rows]
        pts = a.take(rows, axis=0) + frac[:, None] * ab.take(rows, axis=0)
        # A throw-away tree: unbalanced builds faster and queries as fast here.
        samples = kd_tree(pts, balanced_tree=False, compact_nodes=False)
        hits = samples.sparse_distance_matrix(tree, radius, output_type="ndarray")
        cand, robot = rows[hits["i"]], hits["j"].astype(np.intp)
        keep = np.flatnonzero((robot != skip_a[todo[cand]]) & (robot != skip_b[todo[cand]]))
        cand, robot = cand[keep], robot[keep]
        hit = segments_blocked_by_cylinders(q0.take(cand, axis=0), q1.take(cand, axis=0),
                                            positions.take(robot, axis=0), radii[robot], heights[robot])
        blocked[todo[cand[hit]]] = True
        start += count
        count *= _ROUND_GROWTH
        active = active[~blocked[todo[active]] & (n_samples[active] > start)]
    return blocked

