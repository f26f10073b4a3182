"""A tick's sensor readings as the hosts publish them: per robot group, and per robot for the
devices that read all robots at once (for all robots, or a worker's block: core/senses.py)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from composed_sim.core.odometry import PoseReadings, WheelReadings
from composed_sim.devices import DEVICES
from composed_sim.devices.camera import BlobReadings
from composed_sim.devices.range_and_bearing import RangeAndBearingReadings


class GroupReadings:
    """The readings of one robot group of the world file (one model); rows follow ``robots``.

    One attribute per reading of each device with a per-group ``read`` (its ``readings`` and
    ``csr_readings``, in its module of ``devices/``, which says their shapes): the foot-bot's
    ``proximity_distances`` and ``proximity`` [g, k], ``light`` [g, k], ``blobs`` (CSR over the
    group's robots), ``ground`` [g, s], ``lidar`` [g, r]. A device the group does not run: None.
    """

    def __init__(self, model: str, robots: slice):
        self.model = model
        self.robots = robots                        # the group's robots: a contiguous index range
        for name in _ROW_ARRAYS + _CSR:
            setattr(self, name, None)


# GroupReadings' arrays with one row per robot, and its CSR readings.
_ROW_ARRAYS = tuple(name for d in DEVICES for name in d.readings)
_CSR = tuple(name for d in DEVICES for name in d.csr_readings)


@dataclass
class SensorFrame:
    """Every robot's sensor readings at the end of one tick."""
    tick: int
    groups: list[GroupReadings]        # one per robot group of the world file, in its order
    pose: PoseReadings                 # positioning sensor, all robots
    wheels: WheelReadings              # differential steering sensor, all robots
    odometry: np.ndarray               # [n, 3] x, y, yaw in each robot's odom frame
    odometry_twist: np.ndarray         # [n, 2] linear (m/s), angular (rad/s) from the wheels
    # CSR over all robots; None when no robot runs the device.
    range_and_bearing: Optional[RangeAndBearingReadings] = None

    # The device arrays over all robots, for worlds whose robots all share one group layout
    # (the hosts written for the foot-bot flocking experiments read these).
    @property
    def proximity_distances(self) -> np.ndarray:
        return self._only("proximity_distances")

    @property
    def proximity(self) -> np.ndarray:
        return self._only("proximity")

    @property
    def light(self) -> np.ndarray:
        return self._only("light")

    @property
    def blobs(self) -> BlobReadings:
        return self._only("blobs")

    def _only(self, device: str):
        if len(self.groups) != 1:
            raise ValueError(f"frame.{device} is for one-group worlds; this world has {len(self.groups)} "
                             f"groups: read frame.groups[i].{device}")
        value = getattr(self.groups[0], device)
        if value is None:
            raise ValueError(f"the {self.groups[0].model} robots do not run the {device.split('_')[0]} device")
        return value

