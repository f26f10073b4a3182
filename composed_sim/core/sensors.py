"""The foot-bot's proximity ring, light ring and coloured-blob camera, over all robots at once.

Models follow ARGoS 3 (ilpincy/argos3; see docs/architecture.md):
``footbot_proximity_default_sensor.cpp`` + ``proximity_default_sensor.cpp``,
``footbot_light_rotzonly_sensor.cpp`` and ``colored_blob_omnidirectional_camera_rotzonly_sensor.cpp``;
occlusion after ``dynamics2d_engine.cpp``: bodies are footprints extruded from the floor to
their height. ARGoS tests only the point where a ray first meets a footprint; here any point
of the crossing below the height blocks, which differs only for a descending ray that enters
through a body's top (camera → a low LED). Units are SI; ARGoS's camera cm are metres here.

Robot–robot work is done on candidate pairs from a ``scipy.spatial.cKDTree`` of the robot
centres (pass ``tree=`` to share one tree between the sensors of a tick), so the cost follows
the number of nearby pairs, not n².
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.core.geometry import StaticScene, ray_circle_distance, segments_blocked_by_cylinders
from composed_sim.core.poses import wrap_angle
from composed_sim.world.robot_models import LightRing, ProximityRing
from composed_sim.world.schema import Light

# footbot_light_rotzonly_sensor.cpp: a light lights the nearest sensor and 6 on either side.
_LIGHT_HALF_WINDOW = 6

# Camera work per chunk, in (observer, lit LED) candidates; ~15 float64 temporaries each, so
# about 150 MB of them, plus the occlusion walk's samples.
_BLOB_CHUNK = 1 << 20

# Occlusion search: sample spacing along a segment, in robot radii (see blocked_by_robots).
_SPACING_RADII = 4.0


def footbot_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance from the rim (m, inf = nothing) → [...] reading (footbot CalculateReading)."""
    return np.where(distances < 0.009889556, 1.0, 0.0100527 / (distances + 0.000163144))


def epuck_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance (m, inf = nothing) → [...] reading: ARGoS epuck_proximity_default_sensor.cpp,
    298.701 d² − 36.8961 d + 1.08212 up to 5 cm, else 0, clamped to [0, 1]."""
    with np.errstate(invalid="ignore"):   # inf * 0 never happens: inf fails d <= 0.05 first
        value = np.where(distances <= 0.05, (298.701 * distances - 36.8961) * distances + 1.08212, 0.0)
    return np.clip(value, 0.0, 1.0)


def exponential_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance (m, inf = nothing) → [...] exp(-d), 0 for no hit: ARGoS's generic
    proximity_default_sensor.cpp CalculateReading."""
    return np.exp(-distances)


def kheperaiv_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance from the rim (m, inf = nothing) → [...] reading: the ARGoS Khepera IV
    plugin's curve (docs/architecture.md "Khepera IV"), 1 below 4 cm, 0 beyond 12 cm, clamped
    at 0 (the curve dips to −0.007 just before 12 cm)."""
    with np.errstate(over="ignore", invalid="ignore"):
        curve = 4.14 * np.exp(-33.0 * distances) - 0.085
    return np.where(distances < 0.04, 1.0, np.where(distances > 0.12, 0.0, np.maximum(curve, 0.0)))


PROXIMITY_READINGS = {"foot-bot": footbot_proximity_reading, "e-puck": epuck_proximity_reading,
                      "kheperaiv": kheperaiv_proximity_reading,
                      "exponential": exponential_proximity_reading}


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


def _both_ways(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[p, 2] unordered pairs → (a, b) [2p] each, every pair in both orders."""
    return (np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(np.intp),
            np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(np.intp))


def _pair_order(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """The permutation sorting pairs by (a, b), indices < n."""
    if n <= np.iinfo(np.uint16).max:
        # Two stable passes of numpy's radix sort (used for 16-bit keys): O(m), ~10x faster
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
    the robots near points sampled along that stretch, walked from p0 in rounds of 1, 2, 4, ...
    samples; a segment leaves the walk at its first blocker. In a dense swarm most long rays
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
    q0, q1 = p0.take(todo, axis=0), p1.take(todo, axis=0)   # take: ~15x faster than q[idx] on [m, k]
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
    start, count = 0, 1
    while len(active):
        rows, within = _ranges(np.minimum(count, n_samples[active] - start))
        rows = active[rows]
        frac = (start + within + 0.5) / n_samples[rows]
        pts = a.take(rows, axis=0) + frac[:, None] * ab.take(rows, axis=0)
        # A throw-away tree: unbalanced builds ~2x faster and queries as fast here.
        samples = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        hits = samples.sparse_distance_matrix(tree, radius, output_type="ndarray")
        cand, robot = rows[hits["i"]], hits["j"].astype(np.intp)
        keep = np.flatnonzero((robot != skip_a[todo[cand]]) & (robot != skip_b[todo[cand]]))
        cand, robot = cand[keep], robot[keep]
        hit = segments_blocked_by_cylinders(q0.take(cand, axis=0), q1.take(cand, axis=0),
                                            positions.take(robot, axis=0), radii[robot], heights[robot])
        blocked[todo[cand[hit]]] = True
        start += count
        count *= 2
        active = active[~blocked[todo[active]] & (n_samples[active] > start)]
    return blocked


# --- proximity ------------------------------------------------------------------------------

def proximity_ring(positions, headings, radii, heights, ring: ProximityRing, scene: StaticScene, *,
                   noise: float = 0.0, rng: Optional[np.random.Generator] = None,
                   tree: Optional[cKDTree] = None, observers=None) -> tuple[np.ndarray, np.ndarray]:
    """IR rays cast outward from the body of every robot (or of ``observers`` [m] only).

    positions [n, 2], headings [n], radii [n], heights [n] of all robots → (distances [m, k] m
    from the ray's origin, inf when nothing is hit within ``ring.range_m``; readings [m, k] in
    [0, 1] by the ring's calibration). Rays start on the rim at their own angle, or at
    ``ring.origins_m`` (body frame) when given. A ray sees other robots and static bodies
    taller than ``ring.elevation_m``; starting inside one reads 0 m.
    Noise: uniform(-noise, noise) added to every reading, then clamped (ARGoS).
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    _check_noise("noise", noise, rng)
    observers, row_of = _observer_rows(observers, len(positions))
    obs_pos = positions if observers is None else positions[observers]
    obs_head = headings if observers is None else headings[observers]
    n, reach, elevation_m = len(obs_pos), ring.range_m, ring.elevation_m
    sensor = np.asarray(ring.angles_rad)                                                 # [k]
    k = len(sensor)
    # cos(h + a) expanded: n + k trig calls instead of n * k
    ch, sh = np.cos(obs_head)[:, None], np.sin(obs_head)[:, None]
    ca, sa = np.cos(sensor)[None, :], np.sin(sensor)[None, :]
    dirs = np.stack([ch * ca - sh * sa, sh * ca + ch * sa], axis=-1)                     # [n, k, 2]
    if ring.origins_m is None:
        obs_radii = radii if observers is None else radii[observers]
        rim = obs_radii[:, None, None] * dirs                                            # [n, k, 2]
    else:
        ox, oy = np.asarray(ring.origins_m, dtype=np.float64).T[:, None, :]              # [1, k] each
        rim = np.stack([ch * ox - sh * oy, sh * ox + ch * oy], axis=-1)                  # [n, k, 2]
    dist = np.full((n, k), np.inf)
    if scene.n_bodies:
        origins = (obs_pos[:, None, :] + rim).reshape(-1, 2)
        dist = scene.ray_distance(origins, dirs.reshape(-1, 2), reach, min_height=elevation_m).reshape(n, k)
    if len(positions) > 1 and n:
        tree = cKDTree(positions) if tree is None else tree
        lever = radii.max() if ring.origins_m is None else float(np.hypot(*np.asarray(ring.origins_m).T).max())
        obs, tgt = _both_ways(tree.query_pairs(lever + radii.max() + reach, output_type="ndarray"))
        seen = heights[tgt] > elevation_m
        if observers is not None:
            seen &= row_of[obs] >= 0
        seen = np.flatnonzero(seen)
        obs, tgt = obs[seen], tgt[seen]
        row = obs if observers is None else row_of[obs]
        # In the observer's frame (small numbers): ray origins vs the target's relative centre.
        centre = positions.take(tgt, axis=0) - positions.take(obs, axis=0)               # [p, 2]
        d = ray_circle_distance(rim.take(row, axis=0), dirs.take(row, axis=0), centre[:, None, :],
                                radii[tgt][:, None])                                     # [p, k]
        np.minimum.at(dist, row, d)
    dist[dist > reach] = np.inf
    return dist, _uniform_noise(PROXIMITY_READINGS[ring.calibration](dist), noise, rng)


# --- light ----------------------------------------------------------------------------------

def light_ring(positions, headings, radii, heights, ring: LightRing, lights: Sequence[Light],
               scene: StaticScene, *, noise: float = 0.0, rng: Optional[np.random.Generator] = None,
               tree: Optional[cKDTree] = None, observers=None) -> np.ndarray:
    """positions [n, 2], headings [n], radii [n], heights [n] → readings [n, k] in [0, 1]
    (or [m, k] for the robots ``observers`` [m] only; all robots can block the light).

    For each light with intensity I > 0 whose ray from the robot's origin on the floor (z = 0)
    to the light is not blocked by another robot or a static body: d' = (3D distance) / I,
    base = exp(-2 d') if d' <= 2.5 else 0, and the nearest sensor and 6 on either side get
    base * max(0, 1 - 2Δ/π), Δ the angle between the light's bearing and the sensor. Lights
    add; uniform noise; clamp to [0, 1] (ARGoS footbot_light_rotzonly_sensor.cpp, which takes
    the length of the 3D robot-to-light vector).
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    _check_noise("noise", noise, rng)
    observers, _ = _observer_rows(observers, len(positions))
    everyone = np.arange(len(positions)) if observers is None else observers             # [m]
    n = len(everyone)
    sensor = np.asarray(ring.angles_rad)                                                 # [k]
    k = len(sensor)
    out = np.zeros((n, k))
    lights = [lt for lt in lights if lt.intensity > 0.0]
    if n == 0 or not lights:
        return _uniform_noise(out, noise, rng)
    tree = cKDTree(positions) if tree is None else tree
    origin = np.column_stack([positions[everyone], np.zeros(n)])                         # [m, 3]
    obs_head = headings if observers is None else headings[everyone]
    for light in lights:
        target = np.array([light.position[0], light.position[1], light.height_m])
        to_light = target - origin                                                       # [n, 3]
        reduced = np.linalg.norm(to_light, axis=1) / light.intensity
        idx = np.flatnonzero(reduced <= 2.5)       # beyond 2.5 the light adds nothing: skip the ray
        p0, p1 = origin.take(idx, axis=0), np.broadcast_to(target, (len(idx), 3))
        blocked = scene.blocks(p0, p1) | blocked_by_robots(p0, p1, everyone[idx], np.full(len(idx), -1),
                                                           positions, radii, heights, tree)
        idx = idx[~blocked]
        bearing = np.arctan2(to_light[idx, 1], to_light[idx, 0]) - obs_head[idx]
        delta = np.abs(wrap_angle(bearing[:, None] - sensor[None, :]))                 # [m, k]
        nearest = np.argmin(delta, axis=1)
        off = (np.arange(k)[None, :] - nearest[:, None]) % k
        # With 24 sensors 15° apart the sensors outside the window are > 90° away and would
        # weigh 0 anyway; the window matters for other layouts (and never adds twice).
        window = np.minimum(off, k - off) <= _LIGHT_HALF_WINDOW
        weight = np.where(window, np.maximum(0.0, 1.0 - 2.0 * delta / math.pi), 0.0)
        out[idx] += np.exp(-2.0 * reduced[idx])[:, None] * weight
    return _uniform_noise(out, noise, rng)


# --- coloured-blob camera -------------------------------------------------------------------

@dataclass
class BlobReadings:
    """Every robot's blobs, CSR by robot: robot i's are rows offsets[i]:offsets[i+1]."""
    offsets: np.ndarray    # [n+1] int64
    angles: np.ndarray     # [m] bearing relative to the observer's heading, (-pi, pi]
    distances: np.ndarray  # [m] planar, m, from the observer's centre to the LED
    colors: np.ndarray     # [m, 3] uint8 RGB

    def of(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angles [b], distances [b], colors [b, 3]) of robot i's blobs."""
        s = slice(self.offsets[i], self.offsets[i + 1])
        return self.angles[s], self.distances[s], self.colors[s]

    @classmethod
    def empty(cls, n: int) -> "BlobReadings":
        return cls(offsets=np.zeros(n + 1, dtype=np.int64), angles=np.zeros(0), distances=np.zeros(0),
                   colors=np.zeros((0, 3), dtype=np.uint8))


def led_world_positions(positions: np.ndarray, headings: np.ndarray, led_body: np.ndarray) -> np.ndarray:
    """positions [n, 2], headings [n], led_body [L, 3] body-frame → [n, L, 3] world-frame LEDs."""
    positions = np.asarray(positions, dtype=np.float64)
    headings = np.asarray(headings, dtype=np.float64)
    led_body = np.asarray(led_body, dtype=np.float64).reshape(-1, 3)
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    bx, by = led_body[None, :, 0], led_body[None, :, 1]
    return np.stack([positions[:, 0:1] + c * bx - s * by,
                     positions[:, 1:2] + s * bx + c * by,
                     np.broadcast_to(led_body[:, 2], (len(positions), len(led_body)))], axis=-1)


def blob_camera(positions, headings, radii, heights, camera_heights, half_windows, led_world,
                led_colors, scene: StaticScene, *, noise_std: float = 0.0,
                rng: Optional[np.random.Generator] = None, tree: Optional[cKDTree] = None,
                observers=None) -> BlobReadings:
    """The omnidirectional camera's blobs for every robot (or, CSR over ``observers`` [m], for
    those robots only: every robot's LEDs are still seen).

    positions [n, 2], headings [n], radii [n], heights [n], camera_heights [n] m,
    half_windows [n] m (= height · tan(aperture)), led_world [n, L, 3] world-frame LED
    positions, led_colors [n, L, 3] uint8. LED l of robot j is a blob of robot i when it is
    lit (not black), j != i, |dx| and |dy| (world axes) are both below half_windows[i], it is
    lower than the camera, and the segment camera(i) → LED is not blocked by a robot other
    than i (the LED's owner included, as in ARGoS) nor by a static body. Blobs of a robot are ordered by owner, then LED index.
    Noise (ARGoS): the planar camera→LED vector gets |v| · N(0, noise_std) added in a uniform
    direction.
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    n = len(positions)
    camera_heights = np.asarray(camera_heights, dtype=np.float64)
    half_windows = np.asarray(half_windows, dtype=np.float64)
    led_world = np.asarray(led_world, dtype=np.float64)
    led_colors = np.asarray(led_colors)
    for name, a in (("camera_heights", camera_heights), ("half_windows", half_windows)):
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if led_world.ndim != 3 or led_world.shape[::2] != (n, 3):
        raise ValueError(f"led_world must have shape ({n}, L, 3), got {led_world.shape}")
    if led_colors.shape != led_world.shape:
        raise ValueError(f"led_colors must have shape {led_world.shape}, got {led_colors.shape}")
    _check_noise("noise_std", noise_std, rng)

    # Most LEDs are off: the work below follows the lit ones only.
    n_leds = led_world.shape[1]
    rgb = led_colors.astype(np.uint8, copy=False)
    own, led = np.nonzero(rgb[..., 0] | rgb[..., 1] | rgb[..., 2])   # sorted by owner, then LED
    if n < 2 or len(own) == 0:
        return BlobReadings.empty(n if observers is None else len(observers))
    n_lit = np.bincount(own, minlength=n)
    first_lit = np.cumsum(n_lit) - n_lit
    flat = led_world.reshape(-1, 3)                             # [n * L, 3]
    # Observer/owner pairs whose centres are close enough for a lit LED to be in the window.
    reach = np.abs(flat.take(own * n_leds + led, axis=0)[:, :2] - positions.take(own, axis=0)).max()
    tree = cKDTree(positions) if tree is None else tree
    obs, owner = _both_ways(tree.query_pairs(half_windows.max() + reach, p=np.inf, output_type="ndarray"))
    if len(own) < n:
        keep = np.flatnonzero(n_lit[owner] > 0)
        obs, owner = obs[keep], owner[keep]
    observers, row_of = _observer_rows(observers, n)
    if observers is not None:
        keep = np.flatnonzero(row_of[obs] >= 0)
        obs, owner = obs[keep], owner[keep]
    n_out = n if observers is None else len(observers)
    if len(obs) == 0:
        return BlobReadings.empty(n_out)
    order = _pair_order(obs, owner, n)                # the output order: observer, owner, LED
    obs, owner = obs[order], owner[order]
    # Chunks of about _BLOB_CHUNK (observer, LED) candidates: with every LED lit, 10^4 robots
    # give ~10^7 candidates, and their temporaries would need gigabytes at once.
    ends = np.cumsum(n_lit[owner])                    # candidates up to each pair, inclusive
    parts, start, done = [], 0, 0
    while start < len(obs):
        stop = max(start + 1, int(np.searchsorted(ends, done + _BLOB_CHUNK, "right")))
        parts.append(_visible_leds(obs[start:stop], owner[start:stop], n_lit, first_lit, led, flat, positions,
                                   radii, heights, camera_heights, half_windows, scene, tree))
        start, done = stop, ends[stop - 1]
    i, f, rx, ry = parts[0] if len(parts) == 1 else (np.concatenate(x) for x in zip(*parts))

    if noise_std > 0.0:
        length = np.sqrt(rx * rx + ry * ry) * rng.normal(0.0, noise_std, len(rx))
        direction = rng.uniform(0.0, 2.0 * math.pi, len(rx))
        rx, ry = rx + length * np.cos(direction), ry + length * np.sin(direction)
    counts = np.bincount(i, minlength=n)
    offsets = np.zeros(n_out + 1, dtype=np.int64)
    # Blobs are ordered by observer, so an observer subset's rows are already contiguous.
    np.cumsum(counts if observers is None else counts[observers], out=offsets[1:])
    return BlobReadings(offsets=offsets,
                        angles=wrap_angle(np.arctan2(ry, rx) - headings[i]),
                        distances=np.sqrt(rx * rx + ry * ry),
                        colors=rgb.reshape(-1, 3).take(f, axis=0))


def _visible_leds(obs, owner, n_lit, first_lit, led, flat, positions, radii, heights, camera_heights,
                  half_windows, scene, tree):
    """The lit LEDs of `owner` [p] that `obs` [p] sees → (observer, flat LED index, dx, dy) [m] each.

    n_lit [n], first_lit [n]: each robot's count of lit LEDs and where they start in `led` [l];
    flat [n * L, 3] the LED positions, robot-major.
    """
    n_leds = len(flat) // len(positions)
    if n_lit.max() == 1:                                # e.g. flocking: only the beacon is lit
        i, j = obs, owner
        f = j * n_leds + led[first_lit[j]]              # flat LED index
    else:
        rows, within = _ranges(n_lit[owner])
        i, j = obs[rows], owner[rows]
        f = j * n_leds + led[first_lit[j] + within]
    # One 1-D array per coordinate: fancy indexing [m, 2]/[m, 3] arrays is far slower.
    tx, ty, tz = flat[:, 0].take(f), flat[:, 1].take(f), flat[:, 2].take(f)
    rx, ry = tx - positions[:, 0].take(i), ty - positions[:, 1].take(i)
    hw, cz = half_windows[i], camera_heights[i]
    shown = (np.abs(rx) < hw) & (np.abs(ry) < hw) & (tz < cz)
    # Occlusion: static bodies anywhere; robots only where the segment dips below the tallest
    # robot (never for the beacon, which is taller than every foot-bot).
    test = np.flatnonzero(shown if scene.n_bodies else shown & (np.minimum(tz, cz) < heights.max()))
    if len(test):
        led_p = np.stack([tx[test], ty[test], tz[test]], axis=1)
        cam_p = np.stack([tx[test] - rx[test], ty[test] - ry[test], cz[test]], axis=1)
        # Walk from the LED end: a ring LED is hidden, if at all, near its robot.
        # As in ARGoS, only the observer's own body is ignored: a robot's body hides its own
        # far-side ring LEDs (they sit 5 mm outside its rim).
        hidden = scene.blocks(cam_p, led_p) | blocked_by_robots(led_p, cam_p, i[test], np.full(len(test), -1),
                                                                positions, radii, heights, tree)
        shown[test[hidden]] = False
    shown = np.flatnonzero(shown)
    return i[shown], f[shown], rx[shown], ry[shown]
