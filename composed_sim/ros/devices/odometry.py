"""Odometry: the pose integrated from the wheels (readings: core/odometry.Odometry).

``/<r>/odom``, nav_msgs/Odometry: pose in ``<r>/odom`` (the start pose is the identity),
child_frame_id ``<r>/base_link``, twist (linear.x m/s, angular.z rad/s) in base_link. Published and
taken as bytes.
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_into
from composed_sim.ros.devices.positioning import yaw_of
from composed_sim.ros.topic import Topic, base_link, half_yaw, odom_frame
from composed_sim.world.robot_models import ODOMETRY

TOPIC = Topic("odom", Odometry, "sensor",
              "wheel odometry: pose in <r>/odom (the start pose is the identity), child_frame_id "
              "<r>/base_link, twist (linear.x m/s, angular.z rad/s) in base_link")


def message(robot: str) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = odom_frame(robot)
    msg.child_frame_id = base_link(robot)
    return msg


def encoder(robot: str) -> cdr.FixedEncoder:
    """Its ``encode(stamp, x, y, qz, qw, linear, angular)``, the arguments of ``fill``."""
    return cdr.FixedEncoder(message(robot), cdr.odometry_f64_at)


def fill(msg: Odometry, stamp: Time, x: float, y: float, qz: float, qw: float,
         linear: float, angular: float) -> None:
    """Pose (x, y, yaw as qz/qw) in odom, twist (v, ω) in base_link; Python floats."""
    msg.header.stamp = stamp
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    p.x, p.y = x, y
    q.z, q.w = qz, qw
    t.linear.x, t.angular.z = linear, angular


def decode(msg: Odometry) -> tuple[np.ndarray, np.ndarray]:
    """→ pose [3] x, y, yaw in odom; twist [2] linear (m/s), angular (rad/s) in base_link."""
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    return np.array([p.x, p.y, yaw_of(q.z, q.w)]), np.array([t.linear.x, t.angular.z])


def decode_cdr(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    x, y, qz, qw, linear, angular = cdr.decode_odometry(data)
    return np.array([x, y, yaw_of(qz, qw)]), np.array([linear, angular])


class Publisher(DevicePublisher):
    topic, device = TOPIC, ODOMETRY

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        pose = frame.odometry[plan.rows]
        qz, qw = half_yaw(pose[:, 2])
        twist = frame.odometry_twist[plan.rows]
        self.encode_and_send(plan, out, *(column.tolist() for column in
                                          (pose[:, 0], pose[:, 1], qz, qw, twist[:, 0], twist[:, 1])))


DEVICE = Device(ODOMETRY, (TOPIC,), Publisher, reads_into(("odom", "odom_twist"), decode_cdr))
