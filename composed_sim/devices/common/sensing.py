"""What a device's ``read`` gets: one tick's ``Sensing`` and the ``SensedGroup`` to read.

The batch axis is the robots: every device reads all robots' bodies at once (positions, headings,
radii, heights), the static scene with the movable objects where they are now, and one
neighbour index of the robot centres per tick.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Optional, Sequence

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common.floor import Floor
from composed_sim.devices.common.geometry import StaticScene


@dataclass(frozen=True)
class SensedGroup:
    """A robot group of the world file as the simulation and its devices use it."""
    index: int
    model: Any                          # its world/robot_models.RobotModel
    robots: slice                       # its robots: a contiguous index range
    running: tuple[str, ...]            # its switched devices that run
    settings: Any                       # the schema's Devices: each device's settings (``config(name)``)

    @property
    def ids(self) -> np.ndarray:
        return np.arange(self.robots.start, self.robots.stop)


@dataclass
class Sensing:
    """One tick's state as the devices read it (built by ``Simulation.sense``)."""
    positions: np.ndarray              # [n, 2] m
    headings: np.ndarray               # [n] rad
    radii: np.ndarray                  # [n] m
    heights: np.ndarray                # [n] m
    scene: StaticScene
    tree: cKDTree
    noise_of: Callable[[str, np.ndarray], Any]   # (device, robots) → its RowNoise for those rows (noise.py)
    lights: Sequence[Any]              # the world's lights (position, height_m, intensity)
    floor: Optional[Floor]             # None unless some group runs the ground sensors
    camera_heights: np.ndarray         # [n] m
    half_windows: np.ndarray           # [n] m, the camera's square window half-side
    led_colors: np.ndarray             # [n, L, 3] uint8
    led_world: Callable[[np.ndarray, np.ndarray], np.ndarray]   # (robots [l], leds [l]) → [l, 3] world-frame LEDs
    one_group: bool                    # the world has one robot group
    block: Optional[slice] = None      # sense only these robots (a worker process's); None: all

    def observers(self, group: SensedGroup) -> Optional[np.ndarray]:
        """A group's robots that are sensed, as a device's observers (None: every robot)."""
        if self.block is None:
            return None if self.one_group else group.ids
        return self.observer_ids(group)

    def observer_ids(self, group: SensedGroup) -> np.ndarray:
        """[m] the group's robots that are sensed (world indices), in order."""
        if self.block is None:
            return group.ids
        lo, hi = max(group.robots.start, self.block.start), min(group.robots.stop, self.block.stop)
        return np.arange(lo, max(lo, hi))

    def noise(self, device: str, group: SensedGroup):
        """The device's noise for the group's sensed robots this tick (rows in observer order)."""
        return self.noise_of(device, self.observer_ids(group))

