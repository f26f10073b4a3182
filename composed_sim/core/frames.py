"""A tick's sensor readings as the hosts publish them: per robot group, and per robot for the
devices that read all robots at once (for all robots, or a worker's block: core/senses.py)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from composed_sim.core.odometry import PoseReadings, WheelReadings
from composed_sim.devices import READINGS
from composed_sim.devices.camera import BlobReadings
from composed_sim.devices.range_and_bearing import RangeAndBearingReadings


class GroupReadings:
    """The readings of one robot group of the world file (one model); rows follow ``robots``.

    One attribute per reading of each device with a per-group ``read`` (its ``readings`` and
    ``csr_readings``, in its module of ``devices/``, which says their shapes): the foot-bot's
    ``proximity_distances`` and ``proximity`` [g, k], ``light`` [g, k], ``blobs`` (CSR over the
    group's robots), ``ground`` [g, s], ``lidar`` [g, r]. A device the group does not run: None.

    A device's readings are read on first use (``unread``: each of its attributes → the call that
    sets them all, given this object; core/senses.py): a sensor topic nobody subscribes to costs
    no sensing, and what reads them later (a loop function, a recording) gets the same values,
    the noise being drawn per robot, device and tick.
    """

    def __init__(self, model: str, robots: slice,
                 unread: Optional[dict[str, Callable[["GroupReadings"], None]]] = None):
        self.model = model
        self.robots = robots                        # the group's robots: a contiguous index range
        self._unread = unread if unread is not None else {}

    def __getattr__(self, name: str):
        # Only an attribute not set comes here: a reading not read yet (read now), or one of a
        # device the group does not run.
        read = self.__dict__.get("_unread", {}).get(name)
        if read is not None:
            read(self)
            return self.__dict__[name]
        if name in _READINGS:
            return None
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")


# Every GroupReadings attribute a device reads (its arrays with one row per robot, its CSR readings).
_READINGS = frozenset(name for names in READINGS.values() for name in names)


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
    # [n] uint16: each drone's supervisor bits (core/senses.SensingInputs); None: no robot flies.
    supervisor_info: Optional[np.ndarray] = None

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

