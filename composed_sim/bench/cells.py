"""Table cells of the bench report: numbers and ratios, "–" where a value is missing (older
runs.json files lack the newer columns)."""
from __future__ import annotations

from composed_sim.bench.rules import as_number

MISSING = "–"


def number(v, digits: int = 1, scale: float = 1.0) -> str:
    x = as_number(v)
    return MISSING if x is None else f"{x * scale:,.{digits}f}"


def ratio(a, b, digits: int = 2) -> str:
    x, y = as_number(a), as_number(b)
    return MISSING if x is None or y is None or y == 0 else f"{x / y:.{digits}g}" if x / y < 0.01 else f"{x / y:.{digits}f}"
