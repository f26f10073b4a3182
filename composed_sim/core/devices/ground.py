"""Ground: the motor ground sensors under the body, reading the floor's grey level
(docs/architecture.md, "Motor ground sensor"; the floor: core/floor.py).

Its layout: ``world/robot_models.GroundSensors``; its settings: the schema's ``GroundConfig``; its
topic: ``ros/devices/ground.py``.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from composed_sim.core.devices.sensing import SensedGroup, Sensing
from composed_sim.core.floor import Floor, body_points
from composed_sim.core.sensors import _check_noise, _uniform_noise
from composed_sim.world.robot_models import GROUND


def ground_sensors(positions: np.ndarray, headings: np.ndarray, offsets: np.ndarray, floor: Floor, *,
                   noise: float = 0.0, rng: Optional[np.random.Generator] = None) -> np.ndarray:
    """Motor ground sensors of every robot: positions [n, 2], headings [n], offsets [s, 2]
    body frame → readings [n, s] in [0, 1] (grey under each sensor, + uniform(-noise, noise),
    clamped)."""
    _check_noise("noise", noise, rng)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    readings = floor.grey(body_points(positions, np.asarray(headings, dtype=np.float64), offsets))
    return _uniform_noise(readings, noise, rng)


def read(s: Sensing, group: SensedGroup, out) -> None:
    out.ground = ground_sensors(s.positions[group.robots], s.headings[group.robots],
                                np.asarray(group.model.ground.offsets_m), s.floor,
                                noise=group.settings.config(GROUND).noise, rng=s.rngs[GROUND])
