"""Robot index ranges as users write them (``0-639``, ``5``, ``0-9,20-29``), pure: no ROS import.

A controller shard hosts a set of robots given this way; the simulator names missing robots
the same way in its errors.
"""
from __future__ import annotations

from typing import Iterable


class RangeError(ValueError):
    """A robot range that is malformed or outside the world: the message names the bad part."""


def parse_ranges(text: str, n_robots: int) -> list[int]:
    """``"0-9,20-29"`` → sorted robot indices, each within 0 … n_robots-1, no index twice."""
    indices: list[int] = []
    parts = [p.strip() for p in text.split(",")]
    if not text.strip() or any(not p for p in parts):
        raise RangeError(f"robot range {text!r}: expected indices like 0-639, 5 or 0-9,20-29")
    for part in parts:
        first, sep, last = part.partition("-")
        try:
            lo = int(first)
            hi = int(last) if sep else lo
        except ValueError:
            raise RangeError(f"robot range {text!r}: {part!r} is not an index or a FIRST-LAST range") from None
        if lo < 0 or hi < lo:
            raise RangeError(f"robot range {text!r}: {part!r} must be FIRST-LAST with 0 <= FIRST <= LAST")
        if hi >= n_robots:
            raise RangeError(f"robot range {text!r}: {part!r} is outside the world's {n_robots} robots "
                             f"(indices 0-{n_robots - 1})")
        indices.extend(range(lo, hi + 1))
    if len(set(indices)) != len(indices):
        raise RangeError(f"robot range {text!r}: some robots are listed twice")
    return sorted(indices)


def format_ranges(indices: Iterable[int]) -> str:
    """Sorted, compressed: ``[0, 1, 2, 5, 7, 8]`` → ``"0-2,5,7-8"`` (the inverse of parse_ranges)."""
    out: list[str] = []
    run: list[int] = []
    for i in sorted(set(indices)):
        if run and i != run[-1] + 1:
            out.append(_span(run))
            run = []
        run.append(i)
    if run:
        out.append(_span(run))
    return ",".join(out)


def _span(run: list[int]) -> str:
    return str(run[0]) if len(run) == 1 else f"{run[0]}-{run[-1]}"
