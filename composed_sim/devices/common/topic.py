"""What a topic of the contract is, without ROS: its name under the robot's namespace, its message
type by name, its direction, its QoS kind; and the names of a robot's frames.

The ROS layer turns a ``Topic`` into publishers and subscriptions (``ros/topic.py``: the message
class from ``type_name``, the QoS from ``qos``); the devices only write and read the bytes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

WORLD_FRAME = "world"       # the fixed frame: ground truth, /swarm/state, /swarm/markers


@dataclass(frozen=True)
class RawType:
    """A message type with no Python package among the ROS wheels, sent as bytes only
    (``ros/raw_types.py``): its hash as ``ros2 topic info -v`` prints it, and the type of the
    one sequence it holds."""
    rihs01: str
    sequence_of: str


@dataclass(frozen=True)
class Topic:
    name: str            # relative to the robot's namespace ("proximity" → /bot7/proximity)
    type_name: str       # "sensor_msgs/msg/LaserScan"
    direction: str       # "sensor" (simulator → controller), "actuator" (controller → simulator), "frames"
    description: str
    qos: str = "reliable"             # "reliable" (every topic of a tick), "latched" (tf_static)
    raw: Optional[RawType] = None     # a type without a Python package


def topic_name(robot: str, topic: Topic) -> str:
    return f"/{robot}/{topic.name}"


def base_link(robot: str) -> str:
    return f"{robot}/base_link"


def base_scan(robot: str) -> str:
    """The LiDAR's frame (TurtleBot 3's name): base_link shifted by the model's lidar mount."""
    return f"{robot}/base_scan"


def odom_frame(robot: str) -> str:
    return f"{robot}/odom"


def half_yaw(yaws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[n] yaws → (qz, qw) [n] each of the planar quaternions."""
    return np.sin(0.5 * yaws), np.cos(0.5 * yaws)


def yaw_of(qz: float, qw: float) -> float:
    """Yaw of a planar quaternion (0, 0, qz, qw)."""
    return 2.0 * np.arctan2(qz, qw)
