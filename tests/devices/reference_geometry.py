"""Slow, obvious reference geometry shared by the core tests: one segment against one body,
plain floats, written differently from the vectorised kernels they check."""
import math


def ref_span_circle(p0, p1, centre, radius):
    """Parameter interval [lo, hi] ⊂ [0, 1] of the planar segment inside the disc, or None."""
    dx, dy = p1[0] - p0[0], p1[1] - p0[1]
    fx, fy = p0[0] - centre[0], p0[1] - centre[1]
    a, b, c = dx * dx + dy * dy, 2 * (fx * dx + fy * dy), fx * fx + fy * fy - radius * radius
    if a == 0:
        return (0.0, 1.0) if c <= 0 else None
    disc = b * b - 4 * a * c
    if disc < 0:
        return None
    lo, hi = max(0.0, (-b - math.sqrt(disc)) / (2 * a)), min(1.0, (-b + math.sqrt(disc)) / (2 * a))
    return (lo, hi) if lo <= hi else None


def ref_span_box(p0, p1, centre, size, yaw):
    """Slab clipping in the box's own frame (a different method from the kernels')."""
    c, s = math.cos(-yaw), math.sin(-yaw)
    q = [((x - centre[0]) * c - (y - centre[1]) * s, (x - centre[0]) * s + (y - centre[1]) * c)
         for x, y in (p0[:2], p1[:2])]
    lo, hi = 0.0, 1.0
    for ax in (0, 1):
        d, half = q[1][ax] - q[0][ax], size[ax] / 2
        if d == 0:
            if abs(q[0][ax]) > half:
                return None
        else:
            t0, t1 = (-half - q[0][ax]) / d, (half - q[0][ax]) / d
            lo, hi = max(lo, min(t0, t1)), min(hi, max(t0, t1))
    return (lo, hi) if lo <= hi else None
