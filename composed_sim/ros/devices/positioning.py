"""Positioning: the ground-truth pose (readings: core/odometry.positioning).

``/<r>/pose``, geometry_msgs/PoseStamped in frame "world" (the robot is the topic's namespace).
Published and taken as bytes.
"""
from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, reads_into
from composed_sim.ros.global_topics import WORLD_FRAME
from composed_sim.ros.topic import Topic
from composed_sim.world.robot_models import POSITIONING

TOPIC = Topic("pose", PoseStamped, "sensor", "positioning sensor: the robot's ground-truth pose in the world frame")


def message() -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = WORLD_FRAME
    return msg


def fill(msg: PoseStamped, stamp: Time, x: float, y: float, qz: float, qw: float) -> None:
    """A planar pose: position (x, y, 0), orientation (0, 0, qz, qw); Python floats."""
    msg.header.stamp = stamp
    p, q = msg.pose.position, msg.pose.orientation
    p.x, p.y = x, y
    q.z, q.w = qz, qw


def yaw_of(qz: float, qw: float) -> float:
    """Yaw of a planar quaternion (0, 0, qz, qw)."""
    return 2.0 * np.arctan2(qz, qw)


def encoder() -> cdr.FixedEncoder:
    """Its ``encode(stamp, x, y, qz, qw)``, the arguments of ``fill``."""
    return cdr.FixedEncoder(message(), cdr.pose_f64_at)


def decode(msg: PoseStamped) -> np.ndarray:
    """→ [3] x, y (m), yaw (rad) in the world frame."""
    p, q = msg.pose.position, msg.pose.orientation
    return np.array([p.x, p.y, yaw_of(q.z, q.w)])


def decode_cdr(data: bytes) -> np.ndarray:
    x, y, qz, qw = cdr.decode_pose(data)
    return np.array([x, y, yaw_of(qz, qw)])


class Publisher(DevicePublisher):
    topic, device = TOPIC, POSITIONING

    def template(self, robots, i):
        return encoder()

    def publish(self, plan, frame, out):
        xy, q = frame.pose.positions[plan.rows, :2], frame.pose.quaternions[plan.rows]     # q: (x, y, z, w)
        self.encode_and_send(plan, out, *(column.tolist() for column in (xy[:, 0], xy[:, 1], q[:, 2], q[:, 3])))


DEVICE = Device(POSITIONING, (TOPIC,), Publisher, reads_into("pose", decode_cdr))
