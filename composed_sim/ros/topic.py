"""A contract topic (``devices/common/topic.py``: its name, its type by name, its QoS kind) as rclpy
needs it: the message class, the QoS profile, the event callbacks; and sim-time stamps.

The contract's tables (``contract.py``) gather the topics; each device declares its own (``devices/``).
"""
from __future__ import annotations

import functools
import importlib

from builtin_interfaces.msg import Time
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from composed_sim.devices.common.topic import (WORLD_FRAME, Topic, base_link, base_scan, half_yaw,  # noqa: F401 (a topic's parts)
                                               odom_frame, topic_name)
from composed_sim.ros.raw_types import raw_message_type

# Reliable and a few ticks deep, for sensors and commands alike: in lockstep a controller reads
# every tick before the next is published, and an outside monitor still sees every message.
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
# tf_static as tf2's static broadcasters offer it: a late listener still gets the mounts.
STATIC_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
_QOS = {"reliable": QOS, "latched": STATIC_QOS}
# The simulator's and the base class's endpoints create no QoS event handlers. rclpy's default
# ones (a warning on an incompatible QoS or type; the other side still warns) are waitables, and
# the stock executors look each one up in the list of all waitables on every wait: with thousands
# of endpoints that made a single-threaded tick take seconds (docs/speed.md).
PUBLISHER_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)
SUBSCRIPTION_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)


def msg_type(topic: Topic) -> type:
    """The topic's message class (``sensor_msgs/msg/LaserScan`` → ``sensor_msgs.msg.LaserScan``)."""
    return _message_class(topic.type_name, topic.raw)


def message_class(type_name: str) -> type:
    """The message class of an installed type (``std_msgs/msg/String`` → ``std_msgs.msg.String``)."""
    return _message_class(type_name, None)


@functools.lru_cache(maxsize=None)
def _message_class(name: str, raw) -> type:
    def installed(type_name: str) -> type:
        package, _, message = type_name.split("/")
        return getattr(importlib.import_module(f"{package}.msg"), message)
    return installed(name) if raw is None else raw_message_type(name, raw.rihs01, installed(raw.sequence_of))


def qos(topic: Topic) -> QoSProfile:
    return _QOS[topic.qos]


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
