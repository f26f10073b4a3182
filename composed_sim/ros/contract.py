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

import array
from dataclasses import dataclass
from typing import Container, Optional, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, LaserScan, PointCloud2, PointField
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray

from composed_sim.world import robot_models as devices
from composed_sim.world.robot_models import Lidar, RobotModel
from composed_sim.ros import cdr
from composed_sim.ros.raw_types import raw_message_type
from composed_sim.ros.global_topics import CLOCK_TOPIC, SWARM_MARKERS_TOPIC, SWARM_STATE_TOPIC, WORLD_FRAME  # noqa: F401 (part of the contract)


@dataclass(frozen=True)
class Topic:
    name: str            # relative to the robot's namespace ("proximity" → /bot7/proximity)
    msg_type: type
    direction: str       # "sensor" (simulator → controller) or "actuator" (controller → simulator)
    description: str


PROXIMITY = Topic("proximity", LaserScan, "sensor",
                  "IR proximity ring: ranges = distance from the rim in m (+inf: nothing within "
                  "range), intensities = ARGoS reading in [0, 1]; angle_min/increment give the ring")
LIGHT = Topic("light", LaserScan, "sensor",
              "light ring: intensities = reading in [0, 1] per sensor; ranges empty")
BLOBS = Topic("blobs", PointCloud2, "sensor",
              "coloured-blob omnidirectional camera: one point per blob, x/y of the LED in "
              "base_link (m; z = 0, the camera is planar), rgb = 0x00RRGGBB (uint32)")
CMD_VEL = Topic("cmd_vel", TwistStamped, "actuator",
                "differential drive: linear.x m/s, angular.z rad/s; header.stamp must equal the "
                "answered sensor tick's stamp (this message is the controller's answer to a tick); "
                "or geometry_msgs/Twist, unstamped, which answers the tick whose sensors it follows")
# What a controller may publish on cmd_vel (per robot group; the world file's ``cmd_vel`` or the
# controller's publisher says which): the stamped answer of this contract, or the unstamped
# Twist that most ROS nodes publish and the ROS 2-ARGoS bridge took.
ANSWER_TYPES: dict[str, type] = {"stamped": TwistStamped, "unstamped": Twist}
LEDS = Topic("leds", UInt8MultiArray, "actuator",
             "LED colours: data = [n_leds × 3] RGB bytes, ring LEDs first, beacon last; "
             "kept until changed")
GROUND_SENSORS = Topic("ground", PointCloud2, "sensor",
                       "ground sensors: one point per sensor, x/y its position in base_link (m, z = 0), "
                       "intensity = the floor's grey level under it in [0, 1] (float32)")
SCAN = Topic("scan", LaserScan, "sensor",
             "LiDAR in frame <r>/base_scan (the model's mount): ranges in m, REP-117 (+inf: nothing "
             "within range_max, -inf: closer than range_min); angle_min/increment give the rays")
RAB_RX = Topic("rab_rx", PointCloud2, "sensor",
               "range-and-bearing messages heard this tick, one point per sender: x/y/z of its "
               "emitter in base_link (m), range (m), bearing (horizontal, rad), elevation (vertical "
               "bearing, rad), float32; payload = its bytes (uint8, count = payload_bytes)")
POSE = Topic("pose", PoseStamped, "sensor",
             "positioning sensor: the robot's ground-truth pose in the world frame")
ODOM = Topic("odom", Odometry, "sensor",
             "wheel odometry: pose in <r>/odom (the start pose is the identity), child_frame_id "
             "<r>/base_link, twist (linear.x m/s, angular.z rad/s) in base_link")
WHEELS = Topic("wheels", JointState, "sensor",
               "differential steering sensor: joints wheel_left_joint, wheel_right_joint; position = "
               "wheel angle since the start (rad), velocity = wheel speed (rad/s)")
RAB_TX = Topic("rab_tx", UInt8MultiArray, "actuator",
               "range-and-bearing payload: data = exactly payload_bytes bytes, broadcast from the next "
               "tick on (heard one tick later), kept until changed")

# tf's message type has no Python package among the ROS wheels: it travels as bytes
# (ros/raw_types.py), with the type's real name and hash, so any tf listener matches it.
TF_MESSAGE = raw_message_type("tf2_msgs/msg/TFMessage",
                              "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
                              TransformStamped)
TF = Topic("tf", TF_MESSAGE, "frames",
           "the robot's moving frames, each tick: world → <r>/odom (so that world → base_link is the "
           "positioning reading) and <r>/odom → <r>/base_link (the odometry reading)")
TF_STATIC = Topic("tf_static", TF_MESSAGE, "frames",
                  "the robot's fixed sensor mounts (<r>/base_link → <r>/base_scan), once, transient local")

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

SENSOR_TOPICS: tuple[Topic, ...] = (PROXIMITY, LIGHT, BLOBS, GROUND_SENSORS, SCAN, RAB_RX, POSE, ODOM, WHEELS)
ACTUATOR_TOPICS: tuple[Topic, ...] = (CMD_VEL, LEDS, RAB_TX)
FRAME_TOPICS: tuple[Topic, ...] = (TF, TF_STATIC)
TOPICS: dict[str, Topic] = {t.name: t for t in SENSOR_TOPICS + ACTUATOR_TOPICS + FRAME_TOPICS}
# The topics each device gives a robot that runs it (cmd_vel and leds: every robot).
DEVICE_TOPICS: dict[str, tuple[Topic, ...]] = {
    devices.PROXIMITY: (PROXIMITY,), devices.LIGHT: (LIGHT,), devices.CAMERA: (BLOBS,),
    devices.GROUND: (GROUND_SENSORS,), devices.LIDAR: (SCAN,), devices.RANGE_AND_BEARING: (RAB_RX, RAB_TX),
    devices.POSITIONING: (POSE,), devices.ODOMETRY: (ODOM,), devices.DIFFERENTIAL_STEERING: (WHEELS,),
    devices.TF: (TF, TF_STATIC)}


def robot_topics(running) -> tuple[Topic, ...]:
    """The contract topics of a robot running these devices (device names), in TOPICS order."""
    have = {t.name for d in running for t in DEVICE_TOPICS[d]} | {CMD_VEL.name, LEDS.name}
    return tuple(t for t in TOPICS.values() if t.name in have)


CLOCK_TYPE = Clock

# One point per blob. float32 coordinates are ample for a camera with cm-level range.
BLOB_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
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


BLOB_FIELDS = point_fields(BLOB_DTYPE)


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


def publisher_problem(robot: str, topic: str, msg_type: type, robots: Container[str],
                      answer_type: Optional[type] = None) -> Optional[str]:
    """Why ``robot``'s controller may not publish ``msg_type`` on the resolved ``topic``, or None.
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
        if answer_type is not None and msg_type is not answer_type and msg_type in ANSWER_TYPES.values():
            return f"{topic} carries {type_name(answer_type)} (this robot's answers), not {type_name(msg_type)}"
        if msg_type not in ANSWER_TYPES.values():
            return (f"{topic} carries {' or '.join(type_name(t) for t in ANSWER_TYPES.values())} (the topic "
                    f"contract), not {type_name(msg_type)}")
        return None
    if msg_type is not contract.msg_type:
        return f"{topic} carries {type_name(contract.msg_type)} (the topic contract), not {type_name(msg_type)}"
    return None


def stamp_of(tick: int, tick_ns: int) -> Time:
    """Sim time of a tick; integer nanoseconds so stamps are exact and comparable."""
    ns = tick * tick_ns
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_key(stamp: Time) -> int:
    """A stamp as integer nanoseconds, for matching answers to ticks."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


# --- encoding (simulator side) -------------------------------------------------------------

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


def fill_proximity(msg: LaserScan, stamp: Time, distances: np.ndarray, readings: np.ndarray) -> None:
    """distances, readings: [k] for one robot."""
    msg.header.stamp = stamp
    msg.ranges = array.array("f", distances.astype(np.float32).tobytes())
    msg.intensities = array.array("f", readings.astype(np.float32).tobytes())


def fill_light(msg: LaserScan, stamp: Time, readings: np.ndarray) -> None:
    msg.header.stamp = stamp
    msg.intensities = array.array("f", readings.astype(np.float32).tobytes())


def blob_cloud(robot: str) -> PointCloud2:
    return point_cloud(robot, BLOB_DTYPE)


def fill_blobs(msg: PointCloud2, stamp: Time, points: np.ndarray) -> None:
    """points: structured array of BLOB_DTYPE, one per blob."""
    msg.header.stamp = stamp
    msg.width = len(points)
    msg.row_step = msg.point_step * len(points)
    msg.data = points.tobytes()


def blob_points(angles: np.ndarray, distances: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """Blobs given as (bearing [m], planar distance [m], RGB [m,3]) → BLOB_DTYPE points (z = 0)."""
    points = np.empty(len(angles), dtype=BLOB_DTYPE)
    points["x"] = distances * np.cos(angles)
    points["y"] = distances * np.sin(angles)
    points["z"] = 0.0
    c = colors.astype(np.uint32)
    points["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    return points


def led_message(colors: np.ndarray) -> UInt8MultiArray:
    """colors: [n_leds, 3] uint8."""
    colors = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
    msg = UInt8MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label="led", size=len(colors), stride=colors.size),
        MultiArrayDimension(label="rgb", size=3, stride=3),
    ]
    msg.data = colors.tobytes()
    return msg


def twist_stamped(stamp: Time, linear: float, angular: float) -> TwistStamped:
    msg = TwistStamped()
    msg.header.stamp = stamp
    msg.twist.linear.x = float(linear)
    msg.twist.angular.z = float(angular)
    return msg


# Ground sensors: one point per sensor. The positions are fixed; only the intensities change.
GROUND_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])


def ground_cloud(robot: str, n_sensors: int) -> PointCloud2:
    return point_cloud(robot, GROUND_DTYPE, n_sensors)


def ground_points(offsets_m: np.ndarray, readings: np.ndarray) -> np.ndarray:
    """offsets_m [s, 2] body-frame sensor positions, readings [g, s] grey levels → [g, s] GROUND_DTYPE."""
    readings = np.asarray(readings)
    points = np.zeros(readings.shape, dtype=GROUND_DTYPE)
    points["x"] = np.asarray(offsets_m)[:, 0]
    points["y"] = np.asarray(offsets_m)[:, 1]
    points["intensity"] = readings
    return points


def fill_ground(msg: PointCloud2, stamp: Time, points: np.ndarray) -> None:
    """points: [s] GROUND_DTYPE of one robot."""
    msg.header.stamp = stamp
    msg.data = points.tobytes()


def lidar_scan_message(lidar: Lidar, robot: str, scan_time_s: float) -> LaserScan:
    """A LaserScan template for a model's LiDAR (one full scan per tick)."""
    msg = LaserScan()
    msg.header.frame_id = base_scan(robot)
    msg.angle_min = float(lidar.angle_min_rad)
    msg.angle_max = float(lidar.angle_max_rad)
    msg.angle_increment = float(lidar.angle_increment_rad)
    msg.scan_time = float(scan_time_s)
    msg.range_min = float(lidar.min_range_m)
    msg.range_max = float(lidar.max_range_m)
    return msg


def fill_scan(msg: LaserScan, stamp: Time, ranges: np.ndarray) -> None:
    """ranges: [r] m for one robot (float32 already is cheapest: cast once per group)."""
    msg.header.stamp = stamp
    msg.ranges = array.array("f", ranges.astype(np.float32, copy=False).tobytes())


def rab_dtype(payload_bytes: int) -> np.dtype:
    """One range-and-bearing point: emitter position, the ARGoS reading, the payload bytes."""
    return np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("range", "<f4"), ("bearing", "<f4"),
                     ("elevation", "<f4"), ("payload", "u1", (payload_bytes,))])


def rab_cloud(robot: str, payload_bytes: int) -> PointCloud2:
    return point_cloud(robot, rab_dtype(payload_bytes))


def rab_points(ranges: np.ndarray, bearings: np.ndarray, elevations: np.ndarray,
               payloads: np.ndarray) -> np.ndarray:
    """m messages: ranges, horizontal bearings, vertical bearings [m], payloads [m, B] → [m] points."""
    payloads = np.asarray(payloads, dtype=np.uint8)
    points = np.empty(len(ranges), dtype=rab_dtype(payloads.shape[1]))
    planar = ranges * np.cos(elevations)
    points["x"] = planar * np.cos(bearings)
    points["y"] = planar * np.sin(bearings)
    points["z"] = ranges * np.sin(elevations)
    points["range"] = ranges
    points["bearing"] = bearings
    points["elevation"] = elevations
    points["payload"] = payloads
    return points


def fill_rab(msg: PointCloud2, stamp: Time, points: np.ndarray) -> None:
    """points: one robot's rab_points."""
    msg.header.stamp = stamp
    msg.width = len(points)
    msg.row_step = msg.point_step * len(points)
    msg.data = points.tobytes()


def rab_payload_message(data) -> UInt8MultiArray:
    """A payload (bytes or [B] uint8) as the rab_tx message."""
    payload = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray)) \
        else np.asarray(data, dtype=np.uint8).reshape(-1)
    msg = UInt8MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="byte", size=payload.size, stride=payload.size)]
    msg.data = payload.tobytes()
    return msg


def pose_stamped(robot: str) -> PoseStamped:
    """Positioning template: frame "world" (the robot is in the header's child: its namespace)."""
    msg = PoseStamped()
    msg.header.frame_id = WORLD_FRAME
    return msg


def fill_pose(msg: PoseStamped, stamp: Time, x: float, y: float, qz: float, qw: float) -> None:
    """A planar pose: position (x, y, 0), orientation (0, 0, qz, qw); Python floats."""
    msg.header.stamp = stamp
    p, q = msg.pose.position, msg.pose.orientation
    p.x, p.y = x, y
    q.z, q.w = qz, qw


def odometry_message(robot: str) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = odom_frame(robot)
    msg.child_frame_id = base_link(robot)
    return msg


def fill_odometry(msg: Odometry, stamp: Time, x: float, y: float, qz: float, qw: float,
                  linear: float, angular: float) -> None:
    """Pose (x, y, yaw as qz/qw) in odom, twist (v, ω) in base_link; Python floats."""
    msg.header.stamp = stamp
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    p.x, p.y = x, y
    q.z, q.w = qz, qw
    t.linear.x, t.angular.z = linear, angular


WHEEL_JOINTS = ("wheel_left_joint", "wheel_right_joint")   # TurtleBot 3's joint names


def joint_state(robot: str) -> JointState:
    msg = JointState()
    msg.header.frame_id = base_link(robot)
    msg.name = list(WHEEL_JOINTS)
    # Not simulated, so zero, as a TurtleBot 3 reports it. Not empty: Fast CDR pads an empty
    # float64 sequence at the message's end to 8 bytes, and rosbags refuses such a message.
    msg.effort = [0.0] * len(WHEEL_JOINTS)
    return msg


def fill_wheels(msg: JointState, stamp: Time, angles_rad: np.ndarray, velocities_radps: np.ndarray) -> None:
    """[2] (left, right) wheel angles since the start and wheel speeds, of one robot."""
    msg.header.stamp = stamp
    msg.position = array.array("d", angles_rad.astype(np.float64, copy=False).tobytes())
    msg.velocity = array.array("d", velocities_radps.astype(np.float64, copy=False).tobytes())


def half_yaw(yaws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[n] yaws → (qz, qw) [n] each of the planar quaternions."""
    return np.sin(0.5 * yaws), np.cos(0.5 * yaws)


# --- the same messages as serialized bytes (rclpy publishes bytes, raw subscriptions take them) ---
# What the simulator node and the SwarmController base class use: see cdr.py for why.

def proximity_encoder(model: RobotModel, robot: str) -> cdr.ScanEncoder:
    k = len(model.proximity.angles_rad)
    return cdr.ScanEncoder(ring_scan(model.proximity.angles_rad, robot, model.proximity.range_m), k, k)


def light_encoder(model: RobotModel, robot: str) -> cdr.ScanEncoder:
    return cdr.ScanEncoder(ring_scan(model.light.angles_rad, robot, 0.0), 0, len(model.light.angles_rad))


def blobs_encoder(robot: str) -> cdr.CloudEncoder:
    return cdr.CloudEncoder(blob_cloud(robot))


def answer_encoder() -> cdr.TwistEncoder:
    return cdr.TwistEncoder(TwistStamped())


def wheel_speeds(linear: float, angular: float, model: RobotModel) -> tuple[float, float]:
    """ROS velocity command → (left, right) wheel speeds, m/s (ARGoS convention)."""
    half = angular * model.wheel_separation_m / 2.0
    return linear - half, linear + half


def twist_of_wheels(left: float, right: float, model: RobotModel) -> tuple[float, float]:
    """(left, right) wheel speeds, m/s → (linear m/s, angular rad/s)."""
    return (left + right) / 2.0, (right - left) / model.wheel_separation_m
