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

from typing import Literal

import numpy as np

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, NodeRobots
from composed_sim.devices.common.settings import DeviceSwitch
from composed_sim.devices.common.topic import WORLD_FRAME, RawType, Topic, base_link, base_scan, half_yaw, odom_frame, \
    topic_name

NAME = "tf"

# tf's message type has no Python package among the ROS wheels: it travels as bytes
# (ros/raw_types.py), with the type's real name and hash, so any tf listener matches it.
_TF_MESSAGE = RawType("RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
                      "geometry_msgs/msg/TransformStamped")
TOPIC = Topic("tf", "tf2_msgs/msg/TFMessage", "frames",
              "the robot's moving frames, each tick: world → <r>/odom (so that world → base_link is the "
              "positioning reading) and <r>/odom → <r>/base_link (the odometry reading)", raw=_TF_MESSAGE)
STATIC_TOPIC = Topic("tf_static", "tf2_msgs/msg/TFMessage", "frames",
                     "the robot's fixed sensor mounts (<r>/base_link → <r>/base_scan), once, transient local",
                     qos="latched", raw=_TF_MESSAGE)
GLOBAL_TF, GLOBAL_TF_STATIC = "/tf", "/tf_static"


def frame_pairs(robot: str) -> list[tuple[str, str]]:
    """The (parent, child) frames published each tick for ``robot``."""
    return [(WORLD_FRAME, odom_frame(robot)), (odom_frame(robot), base_link(robot))]


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
    out[:, 0, 5], out[:, 0, 6] = half_yaw(drift)
    out[:, 1, 0], out[:, 1, 1] = ox, oy
    out[:, 1, 5], out[:, 1, 6] = half_yaw(oyaw)
    return out


def static_frames(robot: str, model) -> list[tuple[tuple[str, str], tuple[float, ...]]]:
    """The fixed mounts of ``robot``'s sensors that have a frame of their own."""
    if model.lidar is None:
        return []
    x, y, z = model.lidar.mount_m
    return [((base_link(robot), base_scan(robot)), (x, y, z, 0.0, 0.0, 0.0, 1.0))]


class Publisher(DevicePublisher):
    """The tf of one simulator node: each robot's frames on its own /<r>/tf, or gathered into one
    /tf message per tick for the robots on the global topics; the static mounts once, before the
    first tick (kept by the transient-local publishers for listeners that come later)."""
    topic, device = TOPIC, NAME

    def __init__(self, node, robots: NodeRobots):
        super().__init__(node, robots)          # the robots with their own /<r>/tf
        on_global = [i for i in robots.running(NAME) if self.pubs[i] is None]
        self._names = robots.names
        self._gathered: dict[int, np.ndarray] = {}
        self._encoders: dict[tuple[int, ...], cdr.TransformsEncoder] = {}
        self._tf_pub = node.create_topic_publisher(GLOBAL_TF, TOPIC) if on_global else None
        self._static = []       # (publisher, mounts) per message
        for i in self.own_topics(robots):
            if mounts := static_frames(robots.names[i], robots.models[i]):
                pub = node.create_topic_publisher(topic_name(robots.names[i], STATIC_TOPIC), STATIC_TOPIC)
                self._static.append((pub, mounts))
        mounts = [m for i in on_global for m in static_frames(robots.names[i], robots.models[i])]
        if mounts:
            pub = node.create_topic_publisher(GLOBAL_TF_STATIC, STATIC_TOPIC)
            self._static.append((pub, mounts))

    def own_topics(self, robots: NodeRobots) -> list[int]:
        """Those not on the global /tf."""
        return [i for i in robots.running(NAME) if robots.global_tf is None or not robots.global_tf[i]]

    def template(self, robots, i):
        return cdr.TransformsEncoder(frame_pairs(robots.names[i]))

    def publish(self, plan, frame, out):
        poses = moving_frames(frame, plan.rows)                      # [k, 2, 7]
        for k, i in enumerate(plan.local.tolist()):
            if out.failed[i]:
                continue
            if self.pubs[i] is None:
                self._gathered[i] = poses[k]
            elif self.wanted(i, out):
                self.send(i, self.encoders[i].encode(out.sec, out.nanosec, poses[k]), out)

    def finish_tick(self, out) -> None:
        for pub, mounts in self._static:
            encoder = cdr.TransformsEncoder([pair for pair, _ in mounts])
            pub.publish(encoder.encode(out.sec, out.nanosec, [pose for _, pose in mounts]))
        self._static = []
        if not self._gathered:
            return
        robots = tuple(self._gathered)
        if self._tf_pub.get_subscription_count() > 0:
            encoder = self._encoders.get(robots)
            if encoder is None:
                encoder = self._encoders[robots] = cdr.TransformsEncoder(
                    [pair for i in robots for pair in frame_pairs(self._names[i])])
            self._tf_pub.publish(encoder.encode(out.sec, out.nanosec,
                                                np.concatenate([self._gathered[i] for i in robots])))
        self._gathered = {}


class TfConfig(DeviceSwitch):
    # per_robot: /<robot>/tf and /<robot>/tf_static, the multi-robot (Nav2) way: a robot's
    # listeners receive its own frames only. global: /tf and /tf_static, what RViz and Foxglove
    # read by default; every listener then receives every robot's frames (docs/devices.md).
    topics: Literal["per_robot", "global"] = "per_robot"


DEVICE = Device(NAME, (TOPIC, STATIC_TOPIC), Publisher, reader=None, settings=TfConfig, on_robot=False)
