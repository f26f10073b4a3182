"""tf for the robots that switch it on (``devices: {tf: {}}``): REP-105 frames per robot.

Each tick, per robot: ``world → <r>/odom`` and ``<r>/odom → <r>/base_link``. The second is the
odometry reading (it drifts with the wheels' noise, as a real robot's does); the first is what it
takes for ``world → base_link`` to be the positioning reading (the ground truth unless the world
adds positioning noise), as a perfect localiser would publish it. Once, transient local: the fixed
sensor mounts, ``<r>/base_link → <r>/base_scan`` for a LiDAR. Every other sensor's readings are in
``base_link`` itself.

Per robot on ``/<r>/tf`` and ``/<r>/tf_static``, the namespaced convention of multi-robot Nav2:
a robot's own listeners receive its frames only. Or (``tf: {topics: global}``) on ``/tf`` and
``/tf_static``, what RViz and Foxglove read by default: one message per simulator node and tick
with all its robots' frames; every listener then receives every robot's (docs/devices.md).
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
from rclpy.node import Node

from composed_sim.ros import cdr, contract as c
from composed_sim.ros.global_topics import WORLD_FRAME
from composed_sim.world.robot_models import TF, RobotModel

GLOBAL_TF, GLOBAL_TF_STATIC = "/tf", "/tf_static"


def frame_pairs(robot: str) -> list[tuple[str, str]]:
    """The (parent, child) frames published each tick for ``robot``."""
    return [(WORLD_FRAME, c.odom_frame(robot)), (c.odom_frame(robot), c.base_link(robot))]


def moving_frames(frame, rows: np.ndarray) -> np.ndarray:
    """[k, 2, 7] per robot of ``rows``: the (x, y, z, qx, qy, qz, qw) of world → odom and of
    odom → base_link, from a SensorFrame's positioning and odometry readings."""
    x, y = frame.pose.positions[rows, 0], frame.pose.positions[rows, 1]
    yaw = frame.pose.yaws[rows]
    ox, oy, oyaw = frame.odometry[rows, 0], frame.odometry[rows, 1], frame.odometry[rows, 2]
    # world → odom = (world → base_link) · (odom → base_link)⁻¹
    drift = yaw - oyaw
    cos, sin = np.cos(drift), np.sin(drift)
    out = np.zeros((len(rows), 2, 7))
    out[:, 0, 0] = x - (cos * ox - sin * oy)
    out[:, 0, 1] = y - (sin * ox + cos * oy)
    out[:, 0, 5], out[:, 0, 6] = c.half_yaw(drift)
    out[:, 1, 0], out[:, 1, 1] = ox, oy
    out[:, 1, 5], out[:, 1, 6] = c.half_yaw(oyaw)
    return out


def static_frames(robot: str, model: RobotModel) -> list[tuple[tuple[str, str], tuple[float, ...]]]:
    """The fixed mounts of ``robot``'s sensors that have a frame of their own."""
    if model.lidar is None:
        return []
    x, y, z = model.lidar.mount_m
    return [((c.base_link(robot), c.base_scan(robot)), (x, y, z, 0.0, 0.0, 0.0, 1.0))]


class RobotFrames:
    """The tf publishing of one simulator node: its robots' static mounts once, and the frames of
    the robots on the global /tf gathered into one message per tick (the per-robot topics are
    published by the node like its sensors)."""

    def __init__(self, node: Node, names: Sequence[str], models: Sequence[RobotModel],
                 devices: Sequence[frozenset[str]], global_tf: Optional[Sequence[bool]]):
        running = [TF in d for d in devices]
        is_global = [bool(global_tf[i]) if global_tf is not None else False for i in range(len(names))]
        self.per_robot = [r and not g for r, g in zip(running, is_global)]
        self._names = names
        self._global = [i for i, (r, g) in enumerate(zip(running, is_global)) if r and g]
        self._tf_pub = node.create_publisher(c.TF_MESSAGE, GLOBAL_TF, c.QOS, event_callbacks=c.PUBLISHER_EVENTS) \
            if self._global else None
        self._gathered: dict[int, np.ndarray] = {}
        self._encoders: dict[tuple[int, ...], cdr.TransformsEncoder] = {}
        # Static mounts: (publisher, frames, poses) per message.
        self._static = []
        for i, name in enumerate(names):
            mounts = static_frames(name, models[i]) if self.per_robot[i] else []
            if mounts:
                pub = node.create_publisher(c.TF_MESSAGE, c.topic_name(name, c.TF_STATIC), c.STATIC_QOS,
                                            event_callbacks=c.PUBLISHER_EVENTS)
                self._static.append((pub, mounts))
        mounts = [m for i in self._global for m in static_frames(names[i], models[i])]
        if mounts:
            pub = node.create_publisher(c.TF_MESSAGE, GLOBAL_TF_STATIC, c.STATIC_QOS, event_callbacks=c.PUBLISHER_EVENTS)
            self._static.append((pub, mounts))

    def gather(self, i: int, poses: np.ndarray) -> None:
        """Robot i's [2, 7] frames of this tick, for the global /tf message."""
        self._gathered[i] = poses

    def publish(self, stamp) -> None:
        """After a tick's sensors: the gathered /tf message; before the first, the static mounts
        (kept by the transient-local publishers for listeners that come later)."""
        for pub, mounts in self._static:
            encoder = cdr.TransformsEncoder([pair for pair, _ in mounts])
            pub.publish(encoder.encode(stamp.sec, stamp.nanosec, [pose for _, pose in mounts]))
        self._static = []
        if not self._gathered:
            return
        robots = tuple(self._gathered)
        if self._tf_pub.get_subscription_count() > 0:
            encoder = self._encoders.get(robots)
            if encoder is None:
                encoder = self._encoders[robots] = cdr.TransformsEncoder(
                    [pair for i in robots for pair in frame_pairs(self._names[i])])
            self._tf_pub.publish(encoder.encode(stamp.sec, stamp.nanosec,
                                                np.concatenate([self._gathered[i] for i in robots])))
        self._gathered = {}
