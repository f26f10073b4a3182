"""A planar LiDAR on every robot of a group: rays against static bodies and other robots.

The TurtleBot 3 burger's scanner (docs/architecture.md: 360 rays, 0.12-3.5 m, mounted at
(-0.064, 0, 0.122) m). A ray leaves the mount point at the body angle plus the ray's angle and
stops at the first static body or robot taller than the mount (bodies are footprints extruded
from the floor, as everywhere in the core); the robot's own body is ignored (ARGoS's ray queries
skip the sensing robot). Readings follow REP-117 (sensor_msgs/LaserScan): the distance from
the mount point, +inf when nothing is within max range, -inf when the hit is closer than min
range. Noise: N(0, σ) added to every finite reading, then clamped to [min, max] — the
reference names LiDAR noise without a model; Gaussian range noise is what the LDS-01's
datasheet accuracy figures describe.

``/<r>/scan``, sensor_msgs/LaserScan in frame ``<r>/base_scan`` (the model's mount, on
/<r>/tf_static with tf): ranges in m, REP-117; angle_min/increment give the rays. A controller's
Tick: ``scan``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, reads_into
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import _ranges, kd_tree, near_pairs
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import Topic, base_scan

NAME = "lidar"


@dataclass(frozen=True)
class Lidar:
    """A planar scanning range finder: ``n_rays`` evenly spaced from ``angle_min_rad``."""
    n_rays: int
    angle_min_rad: float
    angle_max_rad: float        # the last ray's angle (angle_min + (n_rays - 1) * increment)
    min_range_m: float
    max_range_m: float
    mount_m: tuple[float, float, float]   # (x, y, z) of the scan centre in the body frame

    @property
    def angle_increment_rad(self) -> float:
        return (self.angle_max_rad - self.angle_min_rad) / max(1, self.n_rays - 1)

    def angles_array(self) -> np.ndarray:
        """[r] ray angles in the body frame."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.n_rays)


class LidarConfig(DeviceSwitch):
    noise_std_m: NonNegativeFloat = 0.0


# (pair, ray) candidates per chunk of the robot part: ~10 float64 temporaries each.
_LIDAR_CHUNK = 1 << 20


def lidar_scan(positions: np.ndarray, headings: np.ndarray, radii: np.ndarray, heights: np.ndarray,
               observers: np.ndarray, lidar: Lidar, scene: StaticScene, *, noise_std_m: float = 0.0,
               rng: Optional[np.random.Generator] = None,
               tree: Optional[cKDTree] = None) -> np.ndarray:
    """positions [n, 2], headings [n], radii [n], heights [n] of all robots; observers [m] the
    robots that scan → ranges [m, r] (REP-117, see the module docstring)."""
    positions = np.asarray(positions, dtype=np.float64)
    headings = np.asarray(headings, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    heights = np.asarray(heights, dtype=np.float64)
    observers = np.asarray(observers, dtype=np.intp)
    if not noise_std_m >= 0.0:
        raise ValueError(f"noise_std_m must be >= 0, got {noise_std_m}")
    if noise_std_m > 0.0 and rng is None:
        raise ValueError(f"noise_std_m={noise_std_m} needs a random generator (rng=)")
    m, r = len(observers), lidar.n_rays
    mx, my, mz = lidar.mount_m
    h = headings[observers]
    ch, sh = np.cos(h), np.sin(h)
    origins = positions[observers] + np.column_stack([ch * mx - sh * my, sh * mx + ch * my])   # [m, 2]
    rel = lidar.angles_array()                                                               # [r]
    reach = lidar.max_range_m
    dist = np.full((m, r), np.inf)
    # Only the scanners with a static body within reach cast their rays at the scene (an open
    # floor's obstacles are near few of them).
    near = np.flatnonzero(scene.near(origins, reach)) if m else ()
    if len(near):
        ca, sa, cn, sn = np.cos(rel)[None, :], np.sin(rel)[None, :], ch[near, None], sh[near, None]
        dirs = np.stack([cn * ca - sn * sa, sn * ca + cn * sa], axis=-1)                     # [near, r, 2]
        dist[near] = scene.ray_distance(np.repeat(origins[near], r, axis=0), dirs.reshape(-1, 2), reach,
                                        min_height=mz).reshape(len(near), r)
    n = len(positions)
    if n > 1 and m:
        dist = np.ascontiguousarray(dist)     # _robot_hits writes through a flat view of it
        _robot_hits(dist, positions, radii, heights, observers, origins, h, rel, lidar, tree)
    dist[dist > reach] = np.inf
    if noise_std_m > 0.0:
        finite = np.isfinite(dist)
        # One draw per ray (a robot's r-th ray keeps its draw whatever the others hit).
        dist[finite] = np.clip(dist[finite] + rng.normal(0.0, noise_std_m, dist.shape)[finite],
                               lidar.min_range_m, reach)
    dist[dist < lidar.min_range_m] = -np.inf
    return dist


def _robot_hits(dist, positions, radii, heights, observers, origins, h, rel, lidar: Lidar, tree):
    """Lower dist [m, r] (C-contiguous) in place by the robots the rays meet.

    Pairs (scanner, robot) come from the KD-tree; for each pair only the rays whose direction
    falls in the robot's angular extent seen from the mount are tested, so the work follows
    the few rays per neighbour that can hit, not all r rays times all neighbours.
    """
    n, m, r = len(positions), len(observers), lidar.n_rays
    row_of = np.full(n, -1, dtype=np.intp)
    row_of[observers] = np.arange(m)
    tree = kd_tree(positions) if tree is None else tree
    mount_offset = math.hypot(lidar.mount_m[0], lidar.mount_m[1])
    # From the scanners only when they are a few (a worker's block): not every pair of the swarm.
    a, b = near_pairs(tree, positions, lidar.max_range_m + mount_offset + radii.max(), None if m == n else observers)
    keep = np.flatnonzero((row_of[a] >= 0) & (heights[b] > lidar.mount_m[2]))
    rows, tgt = row_of[a[keep]], b[keep]
    rel_c = positions[tgt] - origins[rows]                        # [p, 2] target centre from the mount
    d = np.hypot(rel_c[:, 0], rel_c[:, 1])
    inside = d <= radii[tgt]
    half = np.where(inside, math.pi, np.arcsin(np.minimum(1.0, radii[tgt] / np.maximum(d, 1e-300))))
    inc = lidar.angle_increment_rad
    full_turn = inc * r >= 2.0 * math.pi - 1e-9
    bearing = np.mod(np.arctan2(rel_c[:, 1], rel_c[:, 0]) - h[rows] - lidar.angle_min_rad, 2.0 * math.pi)
    if full_turn:
        first = np.ceil((bearing - half) / inc).astype(np.intp)
        count = np.clip(np.floor((bearing + half) / inc).astype(np.intp) - first + 1, 0, r)
    else:   # a partial fan (rare): every ray of the pair is tested
        first = np.zeros(len(rows), dtype=np.intp)
        count = np.full(len(rows), r, dtype=np.intp)
    # Per pair, in the scanner's frame with the mount at the origin: the ray t·u meets the circle
    # where t² - 2 t (u·c) + |c|² - r² = 0, c the target's centre.
    cx, cy = rel_c[:, 0], rel_c[:, 1]
    c2 = d * d - radii[tgt] ** 2                                  # <= 0: the mount is inside
    flat_out = dist.reshape(-1)
    ends = np.cumsum(count)
    start = 0
    while start < len(rows):
        done = ends[start - 1] if start else 0
        stop = max(start + 1, int(np.searchsorted(ends, done + _LIDAR_CHUNK, "right")))
        pair, within = _ranges(count[start:stop])
        pair += start
        scanner, ray = rows.take(pair), np.mod(first.take(pair) + within, r)
        cell = scanner * r + ray                                              # flat (scanner, ray)
        ang = h.take(scanner) + rel.take(ray)          # the ray's direction in the world frame
        b = np.cos(ang) * cx.take(pair) + np.sin(ang) * cy.take(pair)         # u·c
        c = c2.take(pair)
        disc = b * b - c
        hit = np.where(c <= 0.0, 0.0, np.where((disc >= 0.0) & (b > 0.0), b - np.sqrt(np.maximum(disc, 0.0)),
                                               np.inf))
        np.minimum.at(flat_out, cell, hit)
        start = stop


def read(s: Sensing, group: SensedGroup, out) -> None:
    out.lidar = lidar_scan(s.positions, s.headings, s.radii, s.heights, s.observer_ids(group), group.model.lidar,
                           s.scene, noise_std_m=group.settings.config(NAME).noise_std_m,
                           rng=s.noise(NAME, group), tree=s.tree)


# --- its topic ------------------------------------------------------------------------------------

TOPIC = Topic("scan", "sensor_msgs/msg/LaserScan", "sensor",
              "LiDAR in frame <r>/base_scan (the model's mount): ranges in m, REP-117 (+inf: nothing "
              "within range_max, -inf: closer than range_min); angle_min/increment give the rays")


def encoder(lidar: Lidar, robot: str, scan_time_s: float) -> cdr.ScanEncoder:
    """A robot's scans (one full scan per tick)."""
    return cdr.ScanEncoder(cdr.scan_bytes(base_scan(robot), lidar.angle_min_rad, lidar.angle_max_rad,
                                          lidar.angle_increment_rad, scan_time_s, lidar.min_range_m,
                                          lidar.max_range_m, lidar.n_rays, 0))


def decode(data: bytes) -> np.ndarray:
    """A scan's bytes → [r] ranges in m from the scanner (±inf per REP-117)."""
    return cdr.decode_scan(data)[0]


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.models[i].lidar, robots.names[i], robots.tick_ns * 1e-9)

    def publish(self, plan, frame, out):
        places, rows = self.to_send(plan, out)
        if rows:
            ranges = frame.groups[plan.group].lidar[plan.within]        # [k, r]
            self.send_scans(places, rows, out, ranges, ranges[:, :0],
                            hand=lambda ranges, intensities: ranges.__getitem__)        # decode's reading


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into("scan", decode), tick_fields=("scan",),
                settings=LidarConfig, layout=Lidar, read=read, readings=("lidar",))
