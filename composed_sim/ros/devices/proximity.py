"""Proximity: the IR ring (readings: core/devices/proximity.py).

``/<r>/proximity``, sensor_msgs/LaserScan in base_link: one ray per sensor at the ring's angles;
ranges = the nearest hit's distance from the rim (m, +inf: nothing within range), intensities =
ARGoS's reading in [0, 1]. Published and taken as bytes.
"""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import LaserScan

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_into
from composed_sim.ros.topic import Topic, ring_scan
from composed_sim.world.robot_models import PROXIMITY, RobotModel

TOPIC = Topic("proximity", LaserScan, "sensor",
              "IR proximity ring: ranges = distance from the rim in m (+inf: nothing within "
              "range), intensities = ARGoS reading in [0, 1]; angle_min/increment give the ring")


def message(model: RobotModel, robot: str) -> LaserScan:
    """Robot's template: the ring's angles and range, no readings."""
    return ring_scan(model.proximity.angles_rad, robot, model.proximity.range_m)


def encoder(model: RobotModel, robot: str) -> cdr.ScanEncoder:
    k = len(model.proximity.angles_rad)
    return cdr.ScanEncoder(message(model, robot), k, k)


def fill(msg: LaserScan, stamp: Time, distances: np.ndarray, readings: np.ndarray) -> None:
    """distances, readings: [k] for one robot."""
    msg.header.stamp = stamp
    msg.ranges = array.array("f", distances.astype(np.float32).tobytes())
    msg.intensities = array.array("f", readings.astype(np.float32).tobytes())


def decode(msg: LaserScan) -> tuple[np.ndarray, np.ndarray]:
    """→ distances [k] (m from the rim, inf = none), readings [k] in [0, 1]."""
    return (np.frombuffer(msg.ranges, dtype=np.float32).astype(float),
            np.frombuffer(msg.intensities, dtype=np.float32).astype(float))


def decode_cdr(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Like ``decode``, from the message's bytes."""
    return cdr.decode_scan(data)


class Publisher(DevicePublisher):
    topic, device = TOPIC, PROXIMITY

    def template(self, robots, i):
        return encoder(robots.models[i], robots.names[i])

    def publish(self, plan, frame, out):
        group = frame.groups[plan.group]
        self.send_scans(plan, out, group.proximity_distances[plan.within], group.proximity[plan.within])


DEVICE = Device(PROXIMITY, (TOPIC,), Publisher, reads_into(("proximity_distances", "proximity"), decode_cdr))
