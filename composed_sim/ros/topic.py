"""What every topic of the contract is made of: the ``Topic`` record, the QoS, the names of a robot's
topics and frames, sim-time stamps, and the message templates several devices share.

The contract's tables (``contract.py``) and each device's topics (``devices/``) are built from these.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan, PointCloud2, PointField


@dataclass(frozen=True)
class Topic:
    name: str            # relative to the robot's namespace ("proximity" → /bot7/proximity)
    msg_type: type
    direction: str       # "sensor" (simulator → controller), "actuator" (controller → simulator), "frames"
    description: str


# Reliable and a few ticks deep, for sensors and commands alike: in lockstep a controller reads
# every tick before the next is published, and an outside monitor still sees every message.
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
# tf_static as tf2's static broadcasters offer it: a late listener still gets the mounts.
STATIC_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
# The simulator's and the base class's endpoints create no QoS event handlers. rclpy's default
# ones (a warning on an incompatible QoS or type; the other side still warns) are waitables, and
# the stock executors look each one up in the list of all waitables on every wait: with thousands
# of endpoints that made a single-threaded tick at 320 robots take 10 s.
PUBLISHER_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)
SUBSCRIPTION_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)


def topic_name(robot: str, topic: Topic) -> str:
    return f"/{robot}/{topic.name}"


def base_link(robot: str) -> str:
    return f"{robot}/base_link"


def base_scan(robot: str) -> str:
    """The LiDAR's frame (TurtleBot 3's name): base_link shifted by the model's lidar mount."""
    return f"{robot}/base_scan"


def odom_frame(robot: str) -> str:
    return f"{robot}/odom"


def type_name(msg_type: type) -> str:
    """``geometry_msgs/msg/TwistStamped``, as ROS tools print it."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def stamp_of(tick: int, tick_ns: int) -> Time:
    """Sim time of a tick; integer nanoseconds so stamps are exact and comparable."""
    ns = tick * tick_ns
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_key(stamp: Time) -> int:
    """A stamp as integer nanoseconds, for matching answers to ticks."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def half_yaw(yaws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[n] yaws → (qz, qw) [n] each of the planar quaternions."""
    return np.sin(0.5 * yaws), np.cos(0.5 * yaws)


_POINT_FIELD_TYPES = {np.dtype("<f4"): PointField.FLOAT32, np.dtype("<u4"): PointField.UINT32,
                      np.dtype("u1"): PointField.UINT8}


def point_fields(dtype: np.dtype) -> list[PointField]:
    """A PointCloud2's fields for points laid out as ``dtype`` (an array field: its count)."""
    fields = []
    for name in dtype.names:
        field_type, offset = dtype.fields[name][:2]
        fields.append(PointField(name=name, offset=offset, datatype=_POINT_FIELD_TYPES[field_type.base],
                                 count=int(np.prod(field_type.shape, dtype=int))))
    return fields


def point_cloud(robot: str, dtype: np.dtype, width: int = 0) -> PointCloud2:
    """A PointCloud2 in ``robot``'s base_link for ``width`` points laid out as ``dtype``."""
    msg = PointCloud2()
    msg.header.frame_id = base_link(robot)
    msg.height = 1
    msg.width = width
    msg.fields = point_fields(dtype)
    msg.is_bigendian = False
    msg.point_step = dtype.itemsize
    msg.row_step = dtype.itemsize * width
    msg.is_dense = True
    return msg


def fill_points(msg: PointCloud2, stamp: Time, points: np.ndarray) -> None:
    """A cloud of one robot's points this tick (structured array laid out as its fields)."""
    msg.header.stamp = stamp
    msg.width = len(points)
    msg.row_step = msg.point_step * len(points)
    msg.data = points.tobytes()


def ring_scan(model_angles: Sequence[float], robot: str, range_max: float) -> LaserScan:
    """A LaserScan template for a sensor ring; its per-tick arrays are filled by the fillers."""
    msg = LaserScan()
    msg.header.frame_id = base_link(robot)
    msg.angle_min = float(model_angles[0])
    msg.angle_increment = float(model_angles[1] - model_angles[0]) if len(model_angles) > 1 else 0.0
    msg.angle_max = float(model_angles[-1])
    msg.range_min = 0.0
    msg.range_max = float(range_max)
    return msg
