"""The engines over cells (core/cells.py): what ``PhysicsWorld`` offers the Simulation, over a state
array of every robot; ``TiledPhysics`` steps every cell in this process (core/regions.py's
``RegionPhysics``, in worker processes)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from composed_sim.core.cell_layout import CellLayout
from composed_sim.core.cells import STATE_FIELDS, CellGroup
from composed_sim.core.physics import checked_wheel_speeds
from composed_sim.devices.common.poses import wrap_angle
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import World


class CellEngine:
    """What ``PhysicsWorld`` offers the Simulation, over a state of every robot [n, 6]: no movable
    objects (a world with them has one space)."""

    n: int

    @property
    def movable(self) -> list:
        return []

    def __init__(self, models: Sequence[RobotModel], positions: np.ndarray, headings: np.ndarray,
                 layout: CellLayout):
        positions = np.asarray(positions, dtype=np.float64)
        headings = np.asarray(headings, dtype=np.float64)
        n = self.n = len(models)
        if positions.shape != (n, 2) or headings.shape != (n,):
            raise ValueError(f"positions must have shape ({n}, 2) and headings ({n},), "
                             f"got {positions.shape} and {headings.shape}")
        if not (np.isfinite(positions).all() and np.isfinite(headings).all()):
            raise ValueError("positions and headings must be finite")
        self.layout = layout
        self._left_mps, self._right_mps = np.zeros(n), np.zeros(n)

    @staticmethod
    def initial_state(positions: np.ndarray, headings: np.ndarray) -> np.ndarray:
        state = np.zeros((len(headings), STATE_FIELDS))
        state[:, 0:2], state[:, 2] = positions, headings
        return state

    def state(self) -> np.ndarray:
        """[n, 6] x, y, angle, vx, vy, w of every robot after the last step."""
        raise NotImplementedError

    def set_wheel_speeds(self, left_mps: np.ndarray, right_mps: np.ndarray) -> None:
        """Store wheel speeds [n] each (m/s); they act from the start of the next step()."""
        self._left_mps, self._right_mps = checked_wheel_speeds(left_mps, right_mps, self.n)

    def wheel_speeds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._left_mps, self._right_mps

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.state()
        return state[:, 0:2].copy(), wrap_angle(state[:, 2])

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        state = self.state()
        return state[:, 3:5].copy(), state[:, 5].copy()

    def movable_poses(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, 2)), np.zeros(0)

    def place_movable(self, index: int, position, yaw_rad: float) -> None:
        raise IndexError(f"movable object {index}: the world has no movable objects")

    def add_movable(self, obstacle) -> int:
        raise ValueError("a movable object needs the physics in one space: this world's robots are in "
                         f"{self.layout.n_cells} cells (set physics.robots_per_cell: 0 and physics.regions: 1)")

    def close(self) -> None:
        """Nothing to release in this process."""


class TiledPhysics(CellEngine):
    """Every cell of ``layout`` in this process, stepped one after the other."""

    def __init__(self, world: World, models: Sequence[RobotModel], positions: np.ndarray, headings: np.ndarray,
                 layout: CellLayout):
        super().__init__(models, positions, headings, layout)
        self._state = self.initial_state(positions, headings)
        self._group = CellGroup(world, models, layout, range(layout.n_cells), self._state)

    def state(self) -> np.ndarray:
        return self._state

    def step(self) -> None:
        out = np.empty_like(self._state)
        self._group.step(self._state, self._left_mps, self._right_mps, out)
        self._state = out
