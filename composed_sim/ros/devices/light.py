"""Light: the light ring (readings: core/devices/light.py).

``/<r>/light``, sensor_msgs/LaserScan in base_link: intensities = the reading in [0, 1] per sensor
at the ring's angles; ranges empty. Published and taken as bytes.
"""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import LaserScan

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_into
from composed_sim.ros.topic import Topic, ring_scan
from composed_sim.world.robot_models import LIGHT, RobotModel

TOPIC = Topic("light", LaserScan, "sensor", "light ring: intensities = reading in [0, 1] per sensor; ranges empty")


def message(model: RobotModel, robot: str) -> LaserScan:
    return ring_scan(model.light.angles_rad, robot, 0.0)


def encoder(model: RobotModel, robot: str) -> cdr.ScanEncoder:
    return cdr.ScanEncoder(message(model, robot), 0, len(model.light.angles_rad))


def fill(msg: LaserScan, stamp: Time, readings: np.ndarray) -> None:
    msg.header.stamp = stamp
    msg.intensities = array.array("f", readings.astype(np.float32).tobytes())


def decode(msg: LaserScan) -> np.ndarray:
    """→ readings [k] in [0, 1]."""
    return np.frombuffer(msg.intensities, dtype=np.float32).astype(float)


def decode_cdr(data: bytes) -> np.ndarray:
    return cdr.decode_scan_intensities(data)


class Publisher(DevicePublisher):
    topic, device = TOPIC, LIGHT

    def template(self, robots, i):
        return encoder(robots.models[i], robots.names[i])

    def publish(self, plan, frame, out):
        self.send_scans(plan, out, None, frame.groups[plan.group].light[plan.within])


DEVICE = Device(LIGHT, (TOPIC,), Publisher, reads_into("light", decode_cdr))
