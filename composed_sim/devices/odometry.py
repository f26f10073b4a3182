"""Odometry: the pose integrated from the wheels (its readings, for every robot: core/odometry.Odometry).

``/<r>/odom``, nav_msgs/Odometry: pose in ``<r>/odom`` (the start pose is the identity),
child_frame_id ``<r>/base_link``, twist (linear.x m/s, angular.z rad/s) in base_link. A
controller's Tick: ``odom`` and ``odom_twist``. Every model has the device; a world file switches
its topic on.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, reads_into
from composed_sim.devices.common.topic import Topic, base_link, half_yaw, odom_frame, yaw_of

NAME = "odometry"

TOPIC = Topic("odom", "nav_msgs/msg/Odometry", "sensor",
              "wheel odometry: pose in <r>/odom (the start pose is the identity), child_frame_id "
              "<r>/base_link, twist (linear.x m/s, angular.z rad/s) in base_link")


def encoder(robot: str) -> cdr.FixedEncoder:
    """Its ``encode(stamp, x, y, qz, qw, linear, angular)``: the pose (x, y, yaw as qz/qw) in odom,
    the twist (v, ω) in base_link."""
    return cdr.FixedEncoder(cdr.odometry_bytes(odom_frame(robot), base_link(robot)), cdr.odometry_f64_at)


def decode(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Odometry bytes → pose [3] x, y, yaw in odom; twist [2] linear (m/s), angular (rad/s) in base_link."""
    x, y, qz, qw, linear, angular = cdr.decode_odometry(data)
    return np.array([x, y, yaw_of(qz, qw)]), np.array([linear, angular])


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        pose = frame.odometry[plan.rows]
        qz, qw = half_yaw(pose[:, 2])
        twist = frame.odometry_twist[plan.rows]
        self.encode_and_send(*self.to_send(plan, out), out, *(column.tolist() for column in
                                          (pose[:, 0], pose[:, 1], qz, qw, twist[:, 0], twist[:, 1])))


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into(("odom", "odom_twist"), decode), tick_fields=("odom", "odom_twist"))
