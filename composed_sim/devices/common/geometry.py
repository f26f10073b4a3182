"""The static scene as arrays, and pure numpy ray/segment kernels.

Everything is 2.5D, as in ARGoS's ``dynamics2d`` engine: a body is a footprint (circle or
convex polygon) extruded from the floor up to its height. A ray is tested in the plane; a 3D
segment is blocked by a body when it crosses the footprint at a point lower than the body.

Kernels broadcast: the shapes in their docstrings are the trailing dimensions, and any leading
``...`` dimensions of the arguments broadcast together (e.g. rays ``[m, 1, 2]`` against circles
``[c, 2]`` give ``[m, c]``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


# Dense (path x static body) work is done in chunks of about this many pairs, so that the
# dozen temporaries of the kernels stay near 100 MB even for 10^4 robots and 10^2 obstacles.
_CHUNK_PAIRS = 1 << 20


# Products of [..., 2] vectors spelled out: numpy's reductions over a length-2 last axis
# (np.sum(..., axis=-1)) are many times slower than this.
def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


# --- kernels --------------------------------------------------------------------------------

def circle_span(origins: np.ndarray, dirs: np.ndarray, centres: np.ndarray,
                radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the lines ``origins + t * dirs`` are inside circles.

    origins [..., 2], dirs [..., 2] (any length, may be zero), centres [..., 2], radii [...]
    → (t_in, t_out) [...] with t_in <= t_out, in units of |dirs|; (inf, -inf) when the line
    misses. A zero ``dirs`` gives (-inf, inf) when the origin is inside, else a miss.
    """
    oc = origins - centres
    a = _dot(dirs, dirs)
    b = _dot(oc, dirs)
    c = _dot(oc, oc) - radii * radii
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        t_in, t_out = (-b - root) / a, (-b + root) / a
    hit = disc >= 0.0
    still = a == 0.0
    t_in = np.where(still, np.where(c <= 0.0, -np.inf, np.inf), np.where(hit, t_in, np.inf))
    t_out = np.where(still, np.where(c <= 0.0, np.inf, -np.inf), np.where(hit, t_out, -np.inf))
    return t_in, t_out


def ray_circle_distance(origins: np.ndarray, dirs: np.ndarray, centres: np.ndarray,
                        radii: np.ndarray) -> np.ndarray:
    """First contact of rays with circles (2D).

    origins [..., 2], dirs [..., 2] unit vectors, centres [..., 2], radii [...] → [...]
    distance along the ray: 0 when the origin is inside the circle, inf when the ray misses it
    or the circle is behind.
    """
    oc = origins - centres
    b = _dot(oc, dirs)
    c = _dot(oc, oc) - radii * radii          # <= 0: the origin is inside
    disc = b * b - c
    ahead = (disc >= 0.0) & (b < 0.0)         # outside, the line meets the circle, in front
    return np.where(c <= 0.0, 0.0, np.where(ahead, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf))


def ray_segment_distance(origins: np.ndarray, dirs: np.ndarray, seg_a: np.ndarray,
                         seg_b: np.ndarray) -> np.ndarray:
    """Where rays cross segments (2D).

    origins [..., 2], dirs [..., 2], seg_a [..., 2], seg_b [..., 2] → [...] the t >= 0 with
    ``origins + t * dirs`` on the segment a–b (distance when dirs are unit vectors; the
    fraction of the way when dirs = end − origin); inf when they don't cross. A ray parallel
    to a segment counts as a miss: the polygon's other edges report the contact.
    """
    e = seg_b - seg_a
    w = seg_a - origins
    den = _cross(dirs, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(w, e) / den
        u = _cross(w, dirs) / den
    hit = (den != 0.0) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    return np.where(hit, t, np.inf)


def ray_segments_first_hit(origins: np.ndarray, dirs: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """origins [m, 2], dirs [m, 2] unit, segments [s, 2, 2] → [m] distance to the nearest
    crossing, inf when none. Dense: [m, s] temporaries."""
    return ray_segment_distance(origins[:, None, :], dirs[:, None, :], segments[:, 0], segments[:, 1]
                                ).min(axis=1, initial=np.inf)


def points_in_polygons(points: np.ndarray, polygons: np.ndarray) -> np.ndarray:
    """points [..., 2], polygons [..., v, 2] convex, counter-clockwise → bool [...].

    The boundary counts as inside.
    """
    a = polygons
    b = np.roll(polygons, -1, axis=-2)
    return np.all(_cross(b - a, points[..., None, :] - a) >= 0.0, axis=-1)


def _low_end(z0: np.ndarray, z1: np.ndarray, t_lo: np.ndarray, t_hi: np.ndarray) -> np.ndarray:
    """The lowest z of a segment on [t_lo, t_hi]: z is linear along it, so the lower end."""
    with np.errstate(invalid="ignore"):   # inf * 0 for a level segment that misses; masked by callers
        return np.minimum(z0 + t_lo * (z1 - z0), z0 + t_hi * (z1 - z0))


def segments_blocked_by_cylinders(p0: np.ndarray, p1: np.ndarray, centres: np.ndarray,
                                  radii: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """3D segments vs vertical cylinders standing on the floor.

    p0 [..., 3], p1 [..., 3], centres [..., 2], radii [...], heights [...] → bool [...]:
    True when the segment crosses the disc at a point whose z is below the height.
    """
    t_in, t_out = circle_span(p0[..., :2], p1[..., :2] - p0[..., :2], centres, radii)
    lo, hi = np.maximum(t_in, 0.0), np.minimum(t_out, 1.0)
    return (lo <= hi) & (_low_end(p0[..., 2], p1[..., 2], lo, hi) < heights)


def segments_blocked_by_prisms(p0: np.ndarray, p1: np.ndarray, polygons: np.ndarray,
                               heights: np.ndarray) -> np.ndarray:
    """3D segments vs vertical prisms (convex CCW footprints) standing on the floor.

    p0 [..., 3], p1 [..., 3], polygons [..., v, 2], heights [...] → bool [...].
    The segment's stretch inside the footprint starts and ends either where it crosses an
    edge or at one of its own end points (when that lies inside); z is linear, so the
    stretch's lowest point is one of those.
    """
    q0, q1 = p0[..., :2], p1[..., :2]
    z0, z1 = p0[..., 2], p1[..., 2]
    t = ray_segment_distance(q0[..., None, :], (q1 - q0)[..., None, :], polygons,
                             np.roll(polygons, -1, axis=-2))                        # [..., v]
    with np.errstate(invalid="ignore"):   # inf * 0 for the misses of a level segment; masked
        z_edges = np.where(t <= 1.0, z0[..., None] + t * (z1 - z0)[..., None], np.inf)
    z_edges = z_edges.min(axis=-1, initial=np.inf)
    z_ends = np.minimum(np.where(points_in_polygons(q0, polygons), z0, np.inf),
                        np.where(points_in_polygons(q1, polygons), z1, np.inf))
    return np.minimum(z_edges, z_ends) < heights


# --- the static scene -----------------------------------------------------------------------

def box_corners(center: tuple[float, float], size: tuple[float, float], yaw_rad: float) -> np.ndarray:
    """[4, 2] corners, counter-clockwise, of a box with its own x/y sides ``size``."""
    hx, hy = size[0] / 2.0, size[1] / 2.0
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    local = np.array([(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)])
    return np.asarray(center, dtype=float) + local @ np.array([[c, s], [-s, c]])


@dataclass(frozen=True)
class StaticScene:
    """Immovable bodies: cylinders, and boxes (obstacles and arena walls) as convex prisms."""
    cyl_centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))    # [c, 2]
    cyl_radii: np.ndarray = field(default_factory=lambda: np.zeros(0))           # [c]
    cyl_heights: np.ndarray = field(default_factory=lambda: np.zeros(0))         # [c]
    box_corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 2)))  # [b, 4, 2] CCW
    box_heights: np.ndarray = field(default_factory=lambda: np.zeros(0))         # [b]

    def __post_init__(self):
        c, b = len(self.cyl_radii), len(self.box_heights)
        for name, arr, shape in (("cyl_centres", self.cyl_centres, (c, 2)),
                                 ("cyl_heights", self.cyl_heights, (c,)),
                                 ("box_corners", self.box_corners, (b, 4, 2))):
            if np.shape(arr) != shape:
                raise ValueError(f"{name} must have shape {shape}, got {np.shape(arr)}")
        # Axis-aligned bounds of every body, cylinders first: [c + b, 2] each.
        lo = np.concatenate([self.cyl_centres - self.cyl_radii[:, None], self.box_corners.min(axis=1)])
        hi = np.concatenate([self.cyl_centres + self.cyl_radii[:, None], self.box_corners.max(axis=1)])
        object.__setattr__(self, "_lo", lo)
        object.__setattr__(self, "_hi", hi)

    def with_bodies(self, cyl_centres: np.ndarray, cyl_radii: np.ndarray, cyl_heights: np.ndarray,
                    box_corners: np.ndarray, box_heights: np.ndarray) -> "StaticScene":
        """This scene plus more bodies (e.g. the movable objects where they are this tick):
        cyl_centres [c, 2], cyl_radii [c], cyl_heights [c], box_corners [b, 4, 2] CCW, box_heights [b]."""
        return StaticScene(cyl_centres=np.concatenate([self.cyl_centres, np.reshape(cyl_centres, (-1, 2))]),
                           cyl_radii=np.concatenate([self.cyl_radii, cyl_radii]),
                           cyl_heights=np.concatenate([self.cyl_heights, cyl_heights]),
                           box_corners=np.concatenate([self.box_corners, np.reshape(box_corners, (-1, 4, 2))]),
                           box_heights=np.concatenate([self.box_heights, box_heights]))

    @property
    def n_bodies(self) -> int:
        return len(self.cyl_radii) + len(self.box_heights)

    @property
    def segments(self) -> np.ndarray:
        """[4b, 2, 2] the boxes' edges (start, end), box by box."""
        return np.stack([self.box_corners, np.roll(self.box_corners, -1, axis=1)], axis=2).reshape(-1, 2, 2)

    @property
    def segment_heights(self) -> np.ndarray:
        """[4b] height of the box each edge belongs to."""
        return np.repeat(self.box_heights, 4)

    def near(self, points: np.ndarray, reach: float) -> np.ndarray:
        """points [m, 2] → bool [m]: some body's bounds come within ``reach`` (per axis) of the
        point. Rays from a point no longer than ``reach`` can meet only the bodies of such points."""
        if self.n_bodies == 0:
            return np.zeros(len(points), dtype=bool)
        lo, hi = points[:, None, :] - reach, points[:, None, :] + reach       # [m, 1, 2]
        return ((lo <= self._hi) & (hi >= self._lo)).all(axis=2).any(axis=1)

    def _candidates(self, lo: np.ndarray, hi: np.ndarray):
        """Yield chunks of (path, body) index pairs whose bounds overlap; lo/hi [m, 2] bound the paths."""
        step = max(1, _CHUNK_PAIRS // max(1, self.n_bodies))
        for s in range(0, len(lo), step):
            low, h = lo[s:s + step, None, :], hi[s:s + step, None, :]   # [chunk, 1, 2] vs [bodies, 2]
            p, b = np.nonzero((low[..., 0] <= self._hi[:, 0]) & (h[..., 0] >= self._lo[:, 0])
                              & (low[..., 1] <= self._hi[:, 1]) & (h[..., 1] >= self._lo[:, 1]))
            yield p + s, b

    def ray_distance(self, origins: np.ndarray, dirs: np.ndarray, max_range: float, *,
                     min_height: float = 0.0) -> np.ndarray:
        """origins [m, 2], dirs [m, 2] unit → [m] distance to the first static body taller than
        ``min_height`` within ``max_range`` (0 when starting inside one), inf when none."""
        out = np.full(len(origins), np.inf)
        if self.n_bodies == 0 or len(origins) == 0:
            return out
        ends = origins + max_range * dirs
        nc = len(self.cyl_radii)
        for path, body in self._candidates(np.minimum(origins, ends), np.maximum(origins, ends)):
            cyl = body < nc
            p, b = path[cyl], body[cyl]
            d = ray_circle_distance(origins[p], dirs[p], self.cyl_centres[b], self.cyl_radii[b])
            d[self.cyl_heights[b] <= min_height] = np.inf
            np.minimum.at(out, p, d)
            p, b = path[~cyl], body[~cyl] - nc
            poly = self.box_corners[b]                                                 # [q, 4, 2]
            d = ray_segment_distance(origins[p, None], dirs[p, None], poly,
                                     np.roll(poly, -1, axis=1)).min(axis=1, initial=np.inf)
            d[points_in_polygons(origins[p], poly)] = 0.0
            d[self.box_heights[b] <= min_height] = np.inf
            np.minimum.at(out, p, d)
        out[out > max_range] = np.inf
        return out

    def blocks(self, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """p0 [m, 3], p1 [m, 3] → bool [m]: the segment passes through a static body."""
        out = np.zeros(len(p0), dtype=bool)
        if self.n_bodies == 0 or len(p0) == 0:
            return out
        nc = len(self.cyl_radii)
        q0, q1 = p0[:, :2], p1[:, :2]
        for path, body in self._candidates(np.minimum(q0, q1), np.maximum(q0, q1)):
            cyl = body < nc
            p, b = path[cyl], body[cyl]
            out[p[segments_blocked_by_cylinders(p0[p], p1[p], self.cyl_centres[b], self.cyl_radii[b],
                                                self.cyl_heights[b])]] = True
            p, b = path[~cyl], body[~cyl] - nc
            out[p[segments_blocked_by_prisms(p0[p], p1[p], self.box_corners[b], self.box_heights[b])]] = True
        return out
