"""Where the physics engine's cells and regions lie, and which robots each cell simulates.

The plane is cut into strips along one axis (``axis``: 0 cuts at x values, 1 at y values), the
*bands*; each band is cut across into *cells* at values of its own. A cell is one pymunk space: it
owns the robots inside its rectangle and simulates, beside them, copies ("ghosts") of the robots
within ``margin_m`` of it, so that a contact across its border is resolved in both cells. A
*region* is a run of consecutive bands stepped by one process; with ``border_contacts`` "ignore"
a cell takes no ghosts from another region, as ARGoS's engines ignore each other's bodies.

The layout is fixed at the start (from the robots' start positions), so a run depends on the world
file alone, never on how many processes step it. Pure numpy: no pymunk here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CellLayout:
    axis: int                          # 0: bands are cut at x values; 1: at y values
    band_cuts: np.ndarray              # [B - 1] increasing: the bands' borders along ``axis``
    cell_cuts: tuple[np.ndarray, ...]  # per band, [C_b - 1] increasing: its cells' borders across
    band_region: np.ndarray            # [B] the region (process) of each band
    margin_m: float                    # ghosts: robots within this distance of a cell, along each axis
    ignore_other_regions: bool         # True: no ghosts across a region's border (ARGoS)

    @property
    def first_cell(self) -> np.ndarray:
        """[B + 1] index of each band's first cell; the last entry is the cell count."""
        return np.concatenate([[0], np.cumsum([len(c) + 1 for c in self.cell_cuts])])

    @property
    def n_cells(self) -> int:
        return int(self.first_cell[-1])

    @property
    def n_regions(self) -> int:
        return int(self.band_region.max()) + 1

    def cell_region(self) -> np.ndarray:
        """[cells] the region of each cell."""
        return np.repeat(self.band_region, [len(c) + 1 for c in self.cell_cuts])

    def owners(self, positions: np.ndarray) -> np.ndarray:
        """[n] the cell that owns each robot at ``positions`` [n, 2] (a border belongs to the higher side)."""
        along, across = positions[:, self.axis], positions[:, 1 - self.axis]
        band = np.searchsorted(self.band_cuts, along, side="right")
        out = np.empty(len(positions), dtype=np.int64)
        first = self.first_cell
        for b, cuts in enumerate(self.cell_cuts):
            mine = band == b
            out[mine] = first[b] + np.searchsorted(cuts, across[mine], side="right")
        return out

    def members(self, positions: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every (cell, robot) pair a cell simulates: its own robots and its ghosts, as two [m]
        arrays sorted by cell, then robot. A robot is a ghost of each other cell whose rectangle
        its square of half-side ``margin_m`` overlaps."""
        m = self.margin_m
        along, across = positions[:, self.axis], positions[:, 1 - self.axis]
        lo_band = np.searchsorted(self.band_cuts, along - m, side="right")
        hi_band = np.searchsorted(self.band_cuts, along + m, side="right")
        first = self.first_cell
        cells, robots = [], []
        for b, cuts in enumerate(self.cell_cuts):
            near = np.flatnonzero((lo_band <= b) & (b <= hi_band))
            lo = np.searchsorted(cuts, across[near] - m, side="right")
            hi = np.searchsorted(cuts, across[near] + m, side="right")
            count = hi - lo + 1
            robots.append(np.repeat(near, count))
            # each robot's run of cells lo … hi: its start repeated, plus 0, 1, … within the run
            starts = np.repeat(first[b] + lo, count)
            runs = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
            cells.append(starts + runs)
        cell, robot = np.concatenate(cells), np.concatenate(robots)
        if self.ignore_other_regions:
            region = self.cell_region()
            keep = region[cell] == region[owner[robot]]
            cell, robot = cell[keep], robot[keep]
        order = np.lexsort((robot, cell))
        return cell[order], robot[order]


def plan_layout(positions: np.ndarray, *, regions: int | None = None, cuts: tuple[float, ...] = (),
                cut_axis: int = 0, robots_per_cell: int, margin_m: float,
                ignore_other_regions: bool) -> CellLayout:
    """The cells of a run whose robots start at ``positions`` [n, 2].

    Regions: ``regions`` strips with about as many robots each (cut at quantiles of the start
    positions, along the wider side of the swarm), or the strips between ``cuts`` (along
    ``cut_axis``). Inside a region of k robots: about k / ``robots_per_cell`` cells (one when
    ``robots_per_cell`` is 0; rounded, so 1.4 times as many robots stay in one cell), in a grid of
    bands and cells cut at quantiles too.
    """
    n = len(positions)
    if regions is not None:
        extent = positions.max(axis=0) - positions.min(axis=0) if n else np.zeros(2)
        axis = int(extent[1] > extent[0])
        region_cuts = _quantile_cuts(positions[:, axis], regions)
    else:
        axis, region_cuts = cut_axis, np.asarray(cuts, dtype=np.float64)
    along, across = positions[:, axis], positions[:, 1 - axis]
    region_of = np.searchsorted(region_cuts, along, side="right")
    band_cuts, cell_cuts, band_region = [], [], []
    for r in range(len(region_cuts) + 1):
        mine = region_of == r
        cells = max(1, round(mine.sum() / robots_per_cell)) if robots_per_cell else 1
        bands = max(1, round(math.sqrt(cells)))
        inner = _quantile_cuts(along[mine], bands)
        if r > 0:
            band_cuts.append(region_cuts[r - 1])
        band_cuts.extend(inner)
        band_of = np.searchsorted(inner, along[mine], side="right")
        for b in range(len(inner) + 1):
            cell_cuts.append(_quantile_cuts(across[mine][band_of == b], math.ceil(cells / bands)))
            band_region.append(r)
    return CellLayout(axis, np.array(band_cuts, dtype=np.float64), tuple(cell_cuts),
                      np.array(band_region, dtype=np.int64), float(margin_m), ignore_other_regions)


def _quantile_cuts(values: np.ndarray, parts: int) -> np.ndarray:
    """[<= parts - 1] increasing cuts that split ``values`` into ``parts`` groups of about equal size
    (fewer where values repeat; none for fewer than two values)."""
    if parts <= 1 or len(values) < 2:
        return np.empty(0)
    cuts = np.quantile(values, np.arange(1, parts) / parts)
    return np.unique(cuts)
