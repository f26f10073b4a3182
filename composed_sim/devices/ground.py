"""Ground: the motor ground sensors under the body, reading the floor's grey level
(docs/architecture.md, "Motor ground sensor"; the floor: devices/common/floor.py).

``/<r>/ground``, sensor_msgs/PointCloud2 in base_link: one point per sensor, x/y its position in
base_link (m, z = 0), intensity = the floor's grey level under it in [0, 1] (float32). A
controller's Tick: ``ground``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from composed_sim.devices.common import cdr_clouds
from composed_sim.devices.common.device import Device, DevicePublisher, reads_cloud_into
from composed_sim.devices.common.floor import Floor, body_points
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import _check_noise, _uniform_noise
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import Topic, base_link

NAME = "ground"


@dataclass(frozen=True)
class GroundSensors:
    """Downward sensors reading the floor's grey level under body-frame points."""
    offsets_m: tuple[tuple[float, float], ...]   # [s] (x, y) body frame


class GroundConfig(DeviceSwitch):
    noise: NonNegativeFloat = 0.0


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
    ids = s.observer_ids(group)
    out.ground = ground_sensors(s.positions[ids], s.headings[ids], np.asarray(group.model.ground.offsets_m),
                                s.floor, noise=group.settings.config(NAME).noise, rng=s.noise(NAME, group))


# --- its topic ------------------------------------------------------------------------------------

TOPIC = Topic("ground", "sensor_msgs/msg/PointCloud2", "sensor",
              "ground sensors: one point per sensor, x/y its position in base_link (m, z = 0), "
              "intensity = the floor's grey level under it in [0, 1] (float32)")
# One point per sensor. The positions are fixed; only the intensities change.
GROUND_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
_FIELDS = tuple((name, offset, datatype) for name, offset, datatype, _ in cdr_clouds.point_fields(GROUND_DTYPE))


def encoder(robot: str) -> cdr_clouds.CloudEncoder:
    return cdr_clouds.CloudEncoder(cdr_clouds.cloud_bytes(base_link(robot), GROUND_DTYPE))


def points_of(offsets_m: np.ndarray, readings: np.ndarray) -> np.ndarray:
    """offsets_m [s, 2] body-frame sensor positions, readings [g, s] grey levels → [g, s] GROUND_DTYPE."""
    readings = np.asarray(readings)
    points = np.zeros(readings.shape, dtype=GROUND_DTYPE)
    points["x"] = np.asarray(offsets_m)[:, 0]
    points["y"] = np.asarray(offsets_m)[:, 1]
    points["intensity"] = readings
    return points


def decode(data: bytes, decoder: Optional[cdr_clouds.CloudDecoder] = None) -> np.ndarray:
    """A cloud's bytes → [s] grey levels in [0, 1], in the model's sensor order. ``decoder``: one
    per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr_clouds.CloudDecoder()).decode(data)
    if fields != _FIELDS or point_step != GROUND_DTYPE.itemsize:
        raise ValueError(f"not a ground-sensor cloud: fields {[name for name, _, _ in fields]} "
                         f"(need x, y, z, intensity float32)")
    return np.frombuffer(points, dtype=GROUND_DTYPE, count=width)["intensity"].astype(float)


def _handed(points: np.ndarray, offsets) -> Callable[[int], np.ndarray]:
    """The k-th cloud's ``decode``, for every cloud of ``points`` at once (devices/common/handoff.py)."""
    intensities = points["intensity"].astype(float)
    return lambda k: intensities[offsets[k]:offsets[k + 1]]


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        places, rows = self.to_send(plan, out)
        if rows:
            points = points_of(plan.model.ground.offsets_m, frame.groups[plan.group].ground[plan.within])  # [k, s]
            k, s = points.shape
            self.send_clouds(places, rows, out, points.reshape(-1), range(0, (k + 1) * s, s), hand=_handed)


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_cloud_into("ground", decode), tick_fields=("ground",),
                settings=GroundConfig, layout=GroundSensors, read=read, readings=("ground",))
