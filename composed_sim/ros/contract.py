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
actuators, published by the controller:
  /<r>/cmd_vel    geometry_msgs/TwistStamped  linear.x (m/s), angular.z (rad/s); header.stamp = the
                                           stamp of the sensor tick it answers (the lockstep answer)
  /<r>/leds       std_msgs/UInt8MultiArray LED colours, [n_leds, 3] RGB, ring LEDs then beacon
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
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from geometry_msgs.msg import TwistStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan, PointCloud2, PointField
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray

from composed_sim.core.robot_models import RobotModel
from composed_sim.ros import cdr


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
                "answered sensor tick's stamp (this message is the controller's answer to a tick)")
LEDS = Topic("leds", UInt8MultiArray, "actuator",
             "LED colours: data = [n_leds × 3] RGB bytes, ring LEDs first, beacon last; "
             "kept until changed")

# Reliable and a few ticks deep, for sensors and commands alike: in lockstep a controller reads
# every tick before the next is published, and an outside monitor still sees every message.
QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)

SENSOR_TOPICS: tuple[Topic, ...] = (PROXIMITY, LIGHT, BLOBS)
ACTUATOR_TOPICS: tuple[Topic, ...] = (CMD_VEL, LEDS)
TOPICS: dict[str, Topic] = {t.name: t for t in SENSOR_TOPICS + ACTUATOR_TOPICS}
CLOCK_TOPIC = "/clock"
CLOCK_TYPE = Clock

# Optional global topics, for people watching or recording a run (never read by controllers).
SWARM_STATE_TOPIC = "/swarm/state"      # in a --record bag: every robot's pose and LED colour per tick
SWARM_MARKERS_TOPIC = "/swarm/markers"  # live with --markers: the swarm as one MarkerArray
WORLD_FRAME = "world"                   # the fixed frame of both

# One point per blob. float32 coordinates are ample for a camera with cm-level range.
BLOB_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
BLOB_FIELDS = [
    PointField(name="x", offset=0, datatype=PointField.FLOAT32, count=1),
    PointField(name="y", offset=4, datatype=PointField.FLOAT32, count=1),
    PointField(name="z", offset=8, datatype=PointField.FLOAT32, count=1),
    PointField(name="rgb", offset=12, datatype=PointField.UINT32, count=1),
]


def topic_name(robot: str, topic: Topic) -> str:
    return f"/{robot}/{topic.name}"


def base_link(robot: str) -> str:
    return f"{robot}/base_link"


def type_name(msg_type: type) -> str:
    """``geometry_msgs/msg/TwistStamped``, as ROS tools print it."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def publisher_problem(robot: str, topic: str, msg_type: type, robots: Container[str]) -> Optional[str]:
    """Why ``robot``'s controller may not publish ``msg_type`` on the resolved ``topic``, or None.

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
    msg = PointCloud2()
    msg.header.frame_id = base_link(robot)
    msg.height = 1
    msg.fields = BLOB_FIELDS
    msg.is_bigendian = False
    msg.point_step = BLOB_DTYPE.itemsize
    msg.is_dense = True
    return msg


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


# --- decoding (controller side): arrays, never raw fields -----------------------------------

@dataclass(frozen=True)
class Blobs:
    angles: np.ndarray      # [m] rad, bearing relative to the heading, CCW
    distances: np.ndarray   # [m] planar distance from the robot centre, m
    colors: np.ndarray      # [m, 3] uint8 RGB
    rgb: Optional[np.ndarray] = None   # [m] uint32 0x00RRGGBB, when decoded from a cloud

    def __len__(self) -> int:
        return len(self.angles)

    def of_color(self, rgb: Sequence[int]) -> "Blobs":
        if self.rgb is not None:
            r, g, b = (int(v) for v in rgb)
            keep = self.rgb == ((r << 16) | (g << 8) | b)
        else:
            keep = np.all(self.colors == np.asarray(rgb, dtype=np.uint8), axis=1)
        return Blobs(self.angles[keep], self.distances[keep], self.colors[keep],
                     None if self.rgb is None else self.rgb[keep])


def ring_angles(msg: LaserScan, count: int) -> np.ndarray:
    """[count] sensor angles of a ring scan."""
    return msg.angle_min + msg.angle_increment * np.arange(count)


def decode_proximity(msg: LaserScan) -> tuple[np.ndarray, np.ndarray]:
    """→ distances [k] (m from the rim, inf = none), readings [k] in [0, 1]."""
    return (np.frombuffer(msg.ranges, dtype=np.float32).astype(float),
            np.frombuffer(msg.intensities, dtype=np.float32).astype(float))


def decode_light(msg: LaserScan) -> np.ndarray:
    """→ readings [k] in [0, 1]."""
    return np.frombuffer(msg.intensities, dtype=np.float32).astype(float)


def decode_blobs(msg: PointCloud2) -> Blobs:
    fields = tuple((f.name, f.offset, f.datatype) for f in msg.fields)
    return _blobs(np.frombuffer(msg.data, dtype=_cloud_dtype(fields, msg.point_step), count=msg.width))


def _blobs(points: np.ndarray) -> Blobs:
    x = points["x"].astype(float)
    y = points["y"].astype(float)
    rgb = points["rgb"]
    colors = np.empty((len(rgb), 3), dtype=np.uint8)
    colors[:, 0], colors[:, 1], colors[:, 2] = rgb >> 16, rgb >> 8, rgb    # uint8 keeps the low byte
    return Blobs(np.arctan2(y, x), np.hypot(x, y), colors, rgb & 0xFFFFFF)


_CLOUD_DTYPES: dict = {}


def _cloud_dtype(fields: tuple, point_step: int) -> np.dtype:
    """The numpy dtype of a blob cloud's points from its fields ((name, offset, datatype) …):
    x, y float32 and rgb uint32, wherever the publisher put them."""
    key = (fields, point_step)
    dtype = _CLOUD_DTYPES.get(key)
    if dtype is None:
        found = {name: (offset, datatype) for name, offset, datatype in fields}
        wanted = {"x": PointField.FLOAT32, "y": PointField.FLOAT32, "rgb": PointField.UINT32}
        if any(found.get(name, (0, None))[1] != datatype for name, datatype in wanted.items()):
            raise ValueError(f"not a blob cloud: fields {sorted(found)} (need x, y float32 and rgb uint32)")
        dtype = _CLOUD_DTYPES[key] = np.dtype({"names": list(wanted), "formats": ["<f4", "<f4", "<u4"],
                                               "offsets": [found[n][0] for n in wanted], "itemsize": point_step})
    return dtype


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


def decode_proximity_cdr(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Like decode_proximity, from the message's bytes."""
    return cdr.decode_scan(data)


def decode_light_cdr(data: bytes) -> np.ndarray:
    return cdr.decode_scan(data)[1]


def decode_blobs_cdr(data: bytes) -> Blobs:
    width, fields, point_step, points = cdr.decode_cloud(data)
    return _blobs(np.frombuffer(points, dtype=_cloud_dtype(fields, point_step), count=width))


def decode_answer_cdr(data: bytes) -> tuple[int, float, float]:
    """cmd_vel bytes → (stamp ns, linear.x, angular.z)."""
    return (cdr.stamp_ns(data), *cdr.decode_twist(data))


def decode_leds(msg: UInt8MultiArray, n_leds: int) -> np.ndarray:
    """→ [n_leds, 3] uint8; ValueError when the message does not carry n_leds colours."""
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size != 3 * n_leds:
        raise ValueError(f"leds message has {data.size} bytes, expected {3 * n_leds} ({n_leds} LEDs × RGB)")
    return data.reshape(n_leds, 3)


def wheel_speeds(linear: float, angular: float, model: RobotModel) -> tuple[float, float]:
    """ROS velocity command → (left, right) wheel speeds, m/s (ARGoS convention)."""
    half = angular * model.wheel_separation_m / 2.0
    return linear - half, linear + half


def twist_of_wheels(left: float, right: float, model: RobotModel) -> tuple[float, float]:
    """(left, right) wheel speeds, m/s → (linear m/s, angular rad/s)."""
    return (left + right) / 2.0, (right - left) / model.wheel_separation_m
