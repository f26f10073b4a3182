"""The physics engine a world gets: one space, cells in this process, or regions in worker processes.

- One space (``core/physics.py``'s ``PhysicsWorld``) while the world needs one cell: up to
  ``physics.robots_per_cell`` robots in one region, or any world with movable objects.
- Cells (``core/cell_engine.py``'s ``TiledPhysics``): the arena cut into spaces of about ``robots_per_cell`` robots
  (core/cell_layout.py, core/cells.py), stepped one after the other in this process.
- Regions (``core/regions.py``'s ``RegionPhysics``): the same cells, each region's stepped by a
  worker process of its own, the state in shared memory.
- A one-region world with several cells: its cells spread over ``physics.processes`` worker
  processes ("auto": one per usable core, at most one per cell), as regions are, the cells and
  the run unchanged.

Cells and regions step the same layout the same way: a world gives the same run whichever of
them steps it (tested), and whichever host runs its controllers.
"""
from __future__ import annotations

from typing import Sequence

import os

import numpy as np

from composed_sim.core.cell_engine import TiledPhysics
from composed_sim.core.cell_layout import CellLayout, plan_layout
from composed_sim.core.physics import PhysicsWorld
from composed_sim.core.regions import RegionPhysics
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import World


def layout_of(world: World, positions: np.ndarray) -> CellLayout:
    """The world's cells and regions, planned from the robots' start positions [n, 2]."""
    p = world.physics
    lines = p.regions if not isinstance(p.regions, int) else None
    return plan_layout(positions, regions=p.regions if lines is None else None,
                       cuts=tuple(lines.x_m or lines.y_m) if lines else (),
                       cut_axis=0 if lines is None or lines.x_m else 1,
                       robots_per_cell=p.robots_per_cell, margin_m=p.ghost_margin_m,
                       ignore_other_regions=p.border_contacts == "ignore")


def physics_engine(world: World, models: Sequence[RobotModel], positions: np.ndarray, headings: np.ndarray,
                   *, processes: bool = True):
    """The engine for ``world`` (see the module's docstring); ``processes=False`` steps the regions'
    cells in this process instead (the same run: for tests and measurements)."""
    positions = np.asarray(positions, dtype=np.float64)
    if any(ob.movable for ob in world.obstacles):
        return PhysicsWorld(world, models, positions, headings)   # the schema refuses regions > 1 then
    layout = layout_of(world, positions)
    if layout.n_cells == 1:
        return PhysicsWorld(world, models, positions, headings)
    if layout.n_regions > 1 and processes:
        return RegionPhysics(world, models, positions, headings, layout)
    count = cell_processes(world, layout.n_cells)
    if count > 1 and processes:
        return RegionPhysics(world, models, positions, headings, layout,
                             groups=[part.tolist() for part in np.array_split(np.arange(layout.n_cells), count)])
    return TiledPhysics(world, models, positions, headings, layout)


def cell_processes(world: World, cells: int) -> int:
    """How many processes step the ``cells`` cells of a one-region world: ``physics.processes``,
    or for "auto" one per usable core (this process's CPU affinity), at most one per cell. The
    cells are stepped from the state at the tick's start, each on its own: how they are grouped
    into processes never changes the run."""
    wanted = world.physics.processes
    cores = len(os.sched_getaffinity(0)) if wanted == "auto" else wanted
    return max(1, min(cores, cells))
