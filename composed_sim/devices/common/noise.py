"""Sensor and actuator noise that does not depend on who computes it.

Every draw is a pure function of (run seed, device, tick, robot, slot): a counter-based generator
(the SplitMix64 finaliser over those keys). So a robot's readings are the same whether the
main process senses all robots at once or a worker process senses only its own block, in any
order, for any number of workers: one seed gives the same trajectories for every K, executor and
mode. A slot numbers a robot's draws within a tick and device: its reading's index (a ray, a
sensor of a ring), or for per-message noise the other party (the LED seen, the sender heard).

The device functions take either this (``RowNoise``, bound to a tick and the robots of their
rows) or a plain ``np.random.Generator`` (tests, one-off use): both have ``uniform``, ``normal``
and ``random`` with a leading row axis, and ``entry_noise`` adapts both to per-entry draws.
"""
from __future__ import annotations

import zlib
from typing import Optional, Union

import numpy as np

_MASK = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15          # 2^64 / φ: spreads consecutive counters over the 64 bits
_ROBOT = 0xD1B54A32D192ED03           # another odd constant, for the robot key
_DRAWS_PER_SLOT = 8                   # entry draws: slot * 8 + draw (a message needs up to 4)


def _mix_int(x: int) -> int:
    """SplitMix64's finaliser on a Python int (64-bit wrap-around)."""
    x &= _MASK
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK
    return x ^ (x >> 31)


def _mix(x: np.ndarray) -> np.ndarray:
    """The same on a uint64 array, in place (numpy's uint64 arithmetic wraps around)."""
    x ^= x >> np.uint64(30)
    x *= np.uint64(0xBF58476D1CE4E5B9)
    x ^= x >> np.uint64(27)
    x *= np.uint64(0x94D049BB133111EB)
    x ^= x >> np.uint64(31)
    return x


def _ndtri(u: np.ndarray) -> np.ndarray:
    """The standard normal's quantile function (scipy loaded on first use, as in sensors.kd_tree)."""
    from scipy.special import ndtri
    return ndtri(u)


def _unit(bits: np.ndarray) -> np.ndarray:
    """uint64 → float64 in (0, 1): 53 bits and half a step, so never 0 or 1."""
    return ((bits >> np.uint64(11)).astype(np.float64) + 0.5) * (1.0 / (1 << 53))


class NoiseStream:
    """One device's noise over a run: ``at(tick, robots)`` gives the draws of a tick."""

    def __init__(self, seed: int, device: str):
        self.key = _mix_int(_mix_int(seed) ^ zlib.crc32(device.encode()))

    def at(self, tick: int, robots) -> "RowNoise":
        """The draws of ``tick`` for rows that are the robots ``robots`` [m] (world indices)."""
        return RowNoise(_mix_int(self.key + (tick + 1) * _GOLDEN), robots)


class RowNoise:
    """A tick's draws for rows of robots: row i, slot j → a value fixed by (robot[i], j)."""

    def __init__(self, tick_key: int, robots):
        self.robots = np.asarray(robots, dtype=np.int64).reshape(-1)
        self._tick_key = tick_key
        self._robot_keys = _robot_keys(tick_key, self.robots)          # [m]

    def _bits(self, size) -> np.ndarray:
        size = (size,) if np.isscalar(size) else tuple(size)
        if not size or size[0] != len(self.robots):
            raise ValueError(f"noise for {len(self.robots)} rows, asked for shape {size}")
        per_row = int(np.prod(size[1:], dtype=np.int64))
        slots = np.arange(per_row, dtype=np.uint64) * np.uint64(_GOLDEN)
        return _mix(self._robot_keys[:, None] + slots[None, :]).reshape(size)

    def random(self, size) -> np.ndarray:
        return _unit(self._bits(size))

    def uniform(self, low, high, size) -> np.ndarray:
        return low + (high - low) * self.random(size)

    def normal(self, loc, scale, size) -> np.ndarray:
        return loc + scale * _ndtri(self.random(size))

    def entries(self, robots: np.ndarray, slots: np.ndarray) -> "EntryNoise":
        """Draws per entry: entry e belongs to robot ``robots[e]`` (a world index), and is numbered
        ``slots[e]`` among that robot's (e.g. the LED it saw): its value does not depend on which
        other entries exist."""
        return EntryNoise(_robot_keys(self._tick_key, robots), np.asarray(slots, dtype=np.uint64))


def _robot_keys(tick_key: int, robots) -> np.ndarray:
    keys = np.asarray(robots, dtype=np.int64).astype(np.uint64) * np.uint64(_ROBOT)
    keys ^= np.uint64(tick_key)
    return _mix(keys)


class EntryNoise:
    """Per-entry draws; ``draw`` numbers the values one entry needs (0 … 7)."""

    def __init__(self, robot_keys: np.ndarray, slots: np.ndarray):
        self._keys = robot_keys + slots * np.uint64((_DRAWS_PER_SLOT * _GOLDEN) & _MASK)

    def random(self, draw: int) -> np.ndarray:
        return _unit(_mix(self._keys + np.uint64((draw * _GOLDEN) & _MASK)))

    def uniform(self, low, high, draw: int) -> np.ndarray:
        return low + (high - low) * self.random(draw)

    def normal(self, loc, scale, draw: int) -> np.ndarray:
        return loc + scale * _ndtri(self.random(draw))


class _GeneratorEntries:
    """``EntryNoise``'s interface over a plain Generator: a fresh draw per call (keys ignored)."""

    def __init__(self, rng: np.random.Generator, count: int):
        self._rng, self._count = rng, count

    def random(self, draw: int) -> np.ndarray:
        return self._rng.random(self._count)

    def uniform(self, low, high, draw: int) -> np.ndarray:
        return self._rng.uniform(low, high, self._count)

    def normal(self, loc, scale, draw: int) -> np.ndarray:
        return self._rng.normal(loc, scale, self._count)


Noise = Union[RowNoise, np.random.Generator]


def entry_noise(noise: Optional[Noise], robots: np.ndarray, slots: np.ndarray):
    """Per-entry draws from either kind of noise source: entry e is robot ``robots[e]``'s entry ``slots[e]``."""
    if isinstance(noise, RowNoise):
        return noise.entries(robots, slots)
    return _GeneratorEntries(noise, len(robots))
