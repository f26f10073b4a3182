"""LiDAR: a planar scanning range finder (readings: core/devices/lidar.py).

``/<r>/scan``, sensor_msgs/LaserScan in frame ``<r>/base_scan`` (the model's mount, on
/<r>/tf_static with tf): ranges in m, REP-117 (+inf: nothing within range_max, -inf: closer than
range_min); angle_min/increment give the rays. Published and taken as bytes.
"""
from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import LaserScan

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_into
from composed_sim.ros.topic import Topic, base_scan
from composed_sim.world.robot_models import LIDAR, Lidar

TOPIC = Topic("scan", LaserScan, "sensor",
              "LiDAR in frame <r>/base_scan (the model's mount): ranges in m, REP-117 (+inf: nothing "
              "within range_max, -inf: closer than range_min); angle_min/increment give the rays")


def message(lidar: Lidar, robot: str, scan_time_s: float) -> LaserScan:
    """A LaserScan template for a model's LiDAR (one full scan per tick)."""
    msg = LaserScan()
    msg.header.frame_id = base_scan(robot)
    msg.angle_min = float(lidar.angle_min_rad)
    msg.angle_max = float(lidar.angle_max_rad)
    msg.angle_increment = float(lidar.angle_increment_rad)
    msg.scan_time = float(scan_time_s)
    msg.range_min = float(lidar.min_range_m)
    msg.range_max = float(lidar.max_range_m)
    return msg


def encoder(lidar: Lidar, robot: str, scan_time_s: float) -> cdr.ScanEncoder:
    return cdr.ScanEncoder(message(lidar, robot, scan_time_s), lidar.n_rays, 0)


def fill(msg: LaserScan, stamp: Time, ranges: np.ndarray) -> None:
    """ranges: [r] m for one robot (float32 already is cheapest: cast once per group)."""
    msg.header.stamp = stamp
    msg.ranges = array.array("f", ranges.astype(np.float32, copy=False).tobytes())


def decode(msg: LaserScan) -> np.ndarray:
    """→ [r] ranges in m from the scanner (±inf per REP-117)."""
    return np.frombuffer(msg.ranges, dtype=np.float32).astype(float)


def decode_cdr(data: bytes) -> np.ndarray:
    return cdr.decode_scan(data)[0]


def angles(msg: LaserScan) -> np.ndarray:
    """[r] ray angles of a scan, rad in its frame."""
    return msg.angle_min + msg.angle_increment * np.arange(len(msg.ranges))


class Publisher(DevicePublisher):
    topic, device = TOPIC, LIDAR

    def template(self, robots, i):
        return encoder(robots.models[i].lidar, robots.names[i], robots.tick_ns * 1e-9)

    def publish(self, plan, frame, out):
        ranges = frame.groups[plan.group].lidar[plan.within]        # [k, r]
        self.send_scans(plan, out, ranges, ranges[:, :0])


DEVICE = Device(LIDAR, (TOPIC,), Publisher, reads_into("scan", decode_cdr))
