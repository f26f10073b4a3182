"""Robot poses as arrays: positions [n, 2] m and headings [n] rad, headings in (-pi, pi]."""
from __future__ import annotations

import math

import numpy as np


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles [any shape] wrapped to (-pi, pi]; an angle already in range comes back unchanged,
    bit for bit (``np.mod(a + pi, 2 pi) - pi`` rounds it twice, and is several times slower)."""
    w = a - 2.0 * math.pi * np.floor((a + math.pi) / (2.0 * math.pi))
    return np.where(w <= -math.pi, w + 2.0 * math.pi, w)


def checked_poses(n: int, positions, headings) -> tuple[np.ndarray, np.ndarray]:
    """``positions`` and ``headings`` as float arrays [n, 2] and [n]; a ValueError names a wrong shape."""
    p = np.asarray(positions, dtype=float)
    h = np.asarray(headings, dtype=float)
    if p.shape != (n, 2):
        raise ValueError(f"positions must be [{n}, 2] (a row per robot), got shape {p.shape}")
    if h.shape != (n,):
        raise ValueError(f"headings must be [{n}] (one per robot), got shape {h.shape}")
    return p, h
