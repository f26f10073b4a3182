"""Ground: the motor ground sensors under the body (readings: core/devices/ground.py).

``/<r>/ground``, sensor_msgs/PointCloud2 in base_link: one point per sensor, x/y its position in
base_link (m, z = 0), intensity = the floor's grey level under it in [0, 1] (float32). Published
and taken as bytes.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import PointCloud2

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_cloud_into
from composed_sim.ros.topic import Topic, point_cloud, point_fields
from composed_sim.world.robot_models import GROUND

TOPIC = Topic("ground", PointCloud2, "sensor",
              "ground sensors: one point per sensor, x/y its position in base_link (m, z = 0), "
              "intensity = the floor's grey level under it in [0, 1] (float32)")

# One point per sensor. The positions are fixed; only the intensities change.
GROUND_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])


def message(robot: str, n_sensors: int) -> PointCloud2:
    return point_cloud(robot, GROUND_DTYPE, n_sensors)


def encoder(robot: str, n_sensors: int) -> cdr.CloudEncoder:
    return cdr.CloudEncoder(message(robot, n_sensors))


def points_of(offsets_m: np.ndarray, readings: np.ndarray) -> np.ndarray:
    """offsets_m [s, 2] body-frame sensor positions, readings [g, s] grey levels → [g, s] GROUND_DTYPE."""
    readings = np.asarray(readings)
    points = np.zeros(readings.shape, dtype=GROUND_DTYPE)
    points["x"] = np.asarray(offsets_m)[:, 0]
    points["y"] = np.asarray(offsets_m)[:, 1]
    points["intensity"] = readings
    return points


def fill(msg: PointCloud2, stamp: Time, points: np.ndarray) -> None:
    """points: [s] GROUND_DTYPE of one robot."""
    msg.header.stamp = stamp
    msg.data = points.tobytes()


def decode(msg: PointCloud2) -> np.ndarray:
    """→ [s] grey levels in [0, 1], in the model's sensor order."""
    return np.frombuffer(msg.data, dtype=GROUND_DTYPE, count=msg.width)["intensity"].astype(float)


def decode_cdr(data: bytes, decoder: Optional[cdr.CloudDecoder] = None) -> np.ndarray:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr.CloudDecoder()).decode(data)
    if fields != _FIELDS or point_step != GROUND_DTYPE.itemsize:
        raise ValueError(f"not a ground-sensor cloud: fields {[name for name, _, _ in fields]} "
                         f"(need x, y, z, intensity float32)")
    return np.frombuffer(points, dtype=GROUND_DTYPE, count=width)["intensity"].astype(float)


_FIELDS = tuple((f.name, f.offset, f.datatype) for f in point_fields(GROUND_DTYPE))


class Publisher(DevicePublisher):
    topic, device = TOPIC, GROUND

    def template(self, robots, i):
        return encoder(robots.names[i], len(robots.models[i].ground.offsets_m))

    def publish(self, plan, frame, out):
        points = points_of(plan.model.ground.offsets_m, frame.groups[plan.group].ground[plan.within])  # [k, s]
        k, s = points.shape
        self.send_clouds(plan, out, points.reshape(-1), range(0, (k + 1) * s, s))


DEVICE = Device(GROUND, (TOPIC,), Publisher, reads_cloud_into("ground", decode_cdr))
