"""The topic contract: every topic a robot has, its standard message type, and how the
sensor arrays of the core travel in those messages.

Both host modes (composed and multi-process) and every controller use exactly this
module, so the topic-level interface cannot drift between them. ``docs/contract.md``
is the prose version of the tables below; a test checks that the two agree.

Per robot ``<r>`` (``bot0`` … ``botN-1``), frames per REP-105 (``<r>/base_link``):

sensors, published by the simulator once per tick, stamped with the tick's sim time:
  /<r>/proximity  sensor_msgs/LaserScan    IR ring: ranges = distance from the rim (m, +inf = no
                                           hit), intensities = ARGoS reading in [0, 1]
  /<r>/light      sensor_msgs/LaserScan    light ring: intensities = reading in [0, 1], no ranges
  /<r>/blobs      sensor_msgs/PointCloud2  coloured blobs: x, y of the seen LED in base_link (m,
                                           z = 0: the camera is planar), rgb 0x00RRGGBB (uint32)
  /<r>/ground     sensor_msgs/PointCloud2  ground sensors: x, y of each sensor in base_link (m),
                                           intensity = floor grey level in [0, 1] (float32)
  /<r>/scan       sensor_msgs/LaserScan    LiDAR, frame <r>/base_scan (the model's mount): ranges (m,
                                           REP-117: +inf nothing within range_max, -inf too close)
  /<r>/rab_rx     sensor_msgs/PointCloud2  range-and-bearing messages heard this tick, one point per
                                           sender: x, y, z (m, base_link), range (m), bearing,
                                           elevation (rad) float32; payload uint8 × payload_bytes
  /<r>/pose       geometry_msgs/PoseStamped  positioning: ground truth in frame "world"
  /<r>/odom       nav_msgs/Odometry        wheel odometry: pose in <r>/odom, twist in <r>/base_link
  /<r>/wheels     sensor_msgs/JointState   differential steering sensor: wheel_left_joint,
                                           wheel_right_joint; position rad since start, velocity rad/s
  A robot has the sensor topics of the devices it runs (the world file's robots[i].devices).
actuators, published by the controller:
  /<r>/cmd_vel    geometry_msgs/TwistStamped  linear.x (m/s), angular.z (rad/s); header.stamp = the
                                           stamp of the sensor tick it answers (the lockstep answer)
  /<r>/leds       std_msgs/UInt8MultiArray LED colours, [n_leds, 3] RGB, ring LEDs then beacon
  /<r>/rab_tx     std_msgs/UInt8MultiArray range-and-bearing payload (payload_bytes bytes), broadcast
                                           from the next tick on, kept until changed
global:
  /clock          rosgraph_msgs/Clock      sim time, once per tick
  /swarm/state    sensor_msgs/PointCloud2  (recordings) one point per robot: x, y, z, yaw, rgb, id
  /swarm/markers  visualization_msgs/MarkerArray  (with --markers) bodies and headings, frame "world"
"""
from __future__ import annotations

from typing import Container, Optional

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist, TwistStamped
from rosgraph_msgs.msg import Clock
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray

from composed_sim.world.robot_models import RobotModel
from composed_sim.devices.common import cdr
from composed_sim.devices import DEVICES, camera, differential_steering, ground, lidar, light, odometry, \
    positioning, proximity, range_and_bearing, tf
from composed_sim.ros.global_topics import CLOCK_TOPIC, SWARM_MARKERS_TOPIC, SWARM_STATE_TOPIC, WORLD_FRAME  # noqa: F401 (part of the contract)
from composed_sim.ros.topic import (PUBLISHER_EVENTS, QOS, STATIC_QOS, SUBSCRIPTION_EVENTS, Topic,  # noqa: F401 (the contract's parts)
                                    base_link, base_scan, half_yaw, msg_type, odom_frame, qos, stamp_key, stamp_of,
                                    topic_name, type_name)

# Every robot's actuators, whatever devices it runs.
CMD_VEL = Topic("cmd_vel", "geometry_msgs/msg/TwistStamped", "actuator",
                "differential drive: linear.x m/s, angular.z rad/s; header.stamp must equal the "
                "answered sensor tick's stamp (this message is the controller's answer to a tick); "
                "or geometry_msgs/Twist, unstamped, which answers the tick whose sensors it follows")
# What a controller may publish on cmd_vel (per robot group; the world file's ``cmd_vel`` or the
# controller's publisher says which): the stamped answer of this contract, or the unstamped
# Twist that most ROS nodes publish and the ROS 2-ARGoS bridge took.
ANSWER_TYPES: dict[str, type] = {"stamped": TwistStamped, "unstamped": Twist}
LEDS = Topic("leds", "std_msgs/msg/UInt8MultiArray", "actuator",
             "LED colours: data = [n_leds × 3] RGB bytes, ring LEDs first, beacon last; "
             "kept until changed")

# The devices' topics (each defined in its module of devices/), by the names the code uses.
PROXIMITY, LIGHT, BLOBS, GROUND_SENSORS, SCAN = proximity.TOPIC, light.TOPIC, camera.TOPIC, ground.TOPIC, lidar.TOPIC
RAB_RX, RAB_TX = range_and_bearing.RX, range_and_bearing.TX
POSE, ODOM, WHEELS = positioning.TOPIC, odometry.TOPIC, differential_steering.TOPIC
TF, TF_STATIC = tf.TOPIC, tf.STATIC_TOPIC
TF_MESSAGE = msg_type(TF)

SENSOR_TOPICS: tuple[Topic, ...] = tuple(t for d in DEVICES for t in d.topics if t.direction == "sensor")
ACTUATOR_TOPICS: tuple[Topic, ...] = (CMD_VEL, LEDS) + tuple(t for d in DEVICES for t in d.topics
                                                             if t.direction == "actuator")
FRAME_TOPICS: tuple[Topic, ...] = tuple(t for d in DEVICES for t in d.topics if t.direction == "frames")
TOPICS: dict[str, Topic] = {t.name: t for t in SENSOR_TOPICS + ACTUATOR_TOPICS + FRAME_TOPICS}
# The topics each device gives a robot that runs it (cmd_vel and leds: every robot).
DEVICE_TOPICS: dict[str, tuple[Topic, ...]] = {d.name: d.topics for d in DEVICES}


def robot_topics(running) -> tuple[Topic, ...]:
    """The contract topics of a robot running these devices (device names), in TOPICS order."""
    have = {t.name for d in running for t in DEVICE_TOPICS[d]} | {CMD_VEL.name, LEDS.name}
    return tuple(t for t in TOPICS.values() if t.name in have)


CLOCK_TYPE = Clock


def namespace_head(name: str) -> str:
    """The first part of a resolved name (``/bot3/scan`` → ``bot3``): the robot whose namespace it
    is in, when a robot has that name."""
    return name.split("/", 2)[1] if name.startswith("/") else ""


def publisher_problem(robot: str, topic: str, published: type, robots: Container[str],
                      answer_type: Optional[type] = None) -> Optional[str]:
    """Why ``robot``'s controller may not publish ``published`` (a message type) on the resolved
    ``topic``, or None.
    ``answer_type``: the cmd_vel type the robot's answers already have, if known.

    A controller publishes its own actuator topics only, with their contract types: another
    robot's topic would make its answers ambiguous (DDS tells a subscriber nothing about which
    writer a sample came from), and a wrong type never matches the simulator's endpoint."""
    parts = topic.split("/")
    if len(parts) != 3 or parts[0] or parts[2] not in TOPICS:
        return None                        # not a contract topic: the controller's own business
    owner, contract = parts[1], TOPICS[parts[2]]
    if owner != robot:
        return f"{topic} is a topic of {owner}, not of {robot}" if owner in robots else None
    if contract.direction == "sensor":
        return f"{topic} is published by the simulator only"
    if contract.direction == "frames":
        return None                        # a controller may add frames (a localiser's map → odom)
    if contract is CMD_VEL:
        if answer_type is not None and published is not answer_type and published in ANSWER_TYPES.values():
            return f"{topic} carries {type_name(answer_type)} (this robot's answers), not {type_name(published)}"
        if published not in ANSWER_TYPES.values():
            return (f"{topic} carries {' or '.join(type_name(t) for t in ANSWER_TYPES.values())} (the topic "
                    f"contract), not {type_name(published)}")
        return None
    if published is not msg_type(contract):
        return f"{topic} carries {contract.type_name} (the topic contract), not {type_name(published)}"
    return None


# --- the actuators' messages -------------------------------------------------------------------

def _led_dims(n_leds: int) -> list[tuple[str, int, int]]:
    """The leds message's layout: (label, size, stride) of each dimension."""
    return [("led", n_leds, 3 * n_leds), ("rgb", 3, 3)]


def _payload_dims(n_bytes: int) -> list[tuple[str, int, int]]:
    """The rab_tx message's layout."""
    return [("byte", n_bytes, n_bytes)]


def _multi_array(dims, data: bytes) -> UInt8MultiArray:
    msg = UInt8MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride) for label, size, stride in dims]
    msg.data = data
    return msg


def led_message(colors: np.ndarray) -> UInt8MultiArray:
    """colors: [n_leds, 3] uint8."""
    colors = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
    return _multi_array(_led_dims(len(colors)), colors.tobytes())


def led_encoder(n_leds: int) -> cdr.UInt8ArrayEncoder:
    """``led_message``'s bytes from the colours' bytes ([n_leds, 3] uint8), as a controller sends them."""
    return cdr.UInt8ArrayEncoder(_led_dims(n_leds))


def payload_message(data) -> UInt8MultiArray:
    """A range-and-bearing payload (bytes or [B] uint8) as the rab_tx message."""
    payload = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray)) \
        else np.asarray(data, dtype=np.uint8).reshape(-1)
    return _multi_array(_payload_dims(payload.size), payload.tobytes())


def payload_encoder(n_bytes: int) -> cdr.UInt8ArrayEncoder:
    """``payload_message``'s bytes from the payload's ``n_bytes`` bytes."""
    return cdr.UInt8ArrayEncoder(_payload_dims(n_bytes))


def twist_stamped(stamp: Time, linear: float, angular: float) -> TwistStamped:
    msg = TwistStamped()
    msg.header.stamp = stamp
    msg.twist.linear.x = float(linear)
    msg.twist.angular.z = float(angular)
    return msg


def answer_encoder() -> cdr.TwistEncoder:
    return cdr.TwistEncoder()


def wheel_speeds(linear: float, angular: float, model: RobotModel) -> tuple[float, float]:
    """ROS velocity command → (left, right) wheel speeds, m/s (ARGoS convention)."""
    half = angular * model.wheel_separation_m / 2.0
    return linear - half, linear + half


def twist_of_wheels(left: float, right: float, model: RobotModel) -> tuple[float, float]:
    """(left, right) wheel speeds, m/s → (linear m/s, angular rad/s)."""
    return (left + right) / 2.0, (right - left) / model.wheel_separation_m
