"""Positioning: the ground-truth pose, with optional noise (its readings, for every robot:
core/odometry.positioning).

``/<r>/pose``, geometry_msgs/PoseStamped in frame "world" (the robot is the topic's namespace).
A controller's Tick: ``pose``. Every model has the device; a world file switches its topic on.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, reads_into
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import WORLD_FRAME, Topic, yaw_of

NAME = "positioning"


class PositioningConfig(DeviceSwitch):
    position_noise_m: NonNegativeFloat = 0.0     # uniform on x and on y
    yaw_noise_rad: NonNegativeFloat = 0.0


TOPIC = Topic("pose", "geometry_msgs/msg/PoseStamped", "sensor",
              "positioning sensor: the robot's ground-truth pose in the world frame")


def encoder() -> cdr.FixedEncoder:
    """Its ``encode(stamp, x, y, z, qz, qw)``: position (x, y, z; z 0 but for a drone), orientation
    (0, 0, qz, qw)."""
    return cdr.FixedEncoder(cdr.pose_stamped_bytes(WORLD_FRAME), cdr.pose_f64_at)


def decode(data: bytes) -> np.ndarray:
    """A pose's bytes → [3] x, y (m), yaw (rad) in the world frame."""
    x, y, qz, qw = cdr.decode_pose(data)
    return np.array([x, y, yaw_of(qz, qw)])


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder()

    def publish(self, plan, frame, out):
        xyz, q = frame.pose.positions[plan.rows], frame.pose.quaternions[plan.rows]     # q: (x, y, z, w)
        self.encode_and_send(*self.to_send(plan, out), out,
                             *(column.tolist() for column in (xyz[:, 0], xyz[:, 1], xyz[:, 2], q[:, 2], q[:, 3])))


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into("pose", decode), tick_fields=("pose",),
                settings=PositioningConfig)
