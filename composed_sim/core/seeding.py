"""Random streams: one run seed fixes everything, each consumer draws from its own stream
(the sensors' and wheels' noise: devices/common/noise.py, per robot and tick).

Independent streams mean that adding noise to one device never shifts the placement or another
device's draws, and a controller's draws never depend on callback order or executor threads.
"""
from __future__ import annotations

import zlib

import numpy as np

STREAM_PLACEMENT = 0
# (1 was the devices' noise: now drawn per robot and tick, devices/common/noise.py)
STREAM_CONTROLLERS = 2
STREAM_OBSTACLES = 3      # obstacles an ARGoS <distribute> places at import


def stream(seed: int, purpose: int) -> np.random.Generator:
    return np.random.default_rng([seed, purpose])


def robot_rng(seed: int, robot: str) -> np.random.Generator:
    """A controller's own generator: depends on the run seed and its robot name only."""
    return np.random.default_rng([seed, STREAM_CONTROLLERS, zlib.crc32(robot.encode())])


