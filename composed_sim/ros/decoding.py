"""The controller side of the topic contract: messages (or their bytes) → numpy arrays, never raw
fields. The simulator decodes the controllers' answers, LEDs and payloads with the same functions."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState, LaserScan, PointCloud2, PointField
from std_msgs.msg import UInt8MultiArray

from composed_sim.ros import cdr
from composed_sim.ros.contract import GROUND_DTYPE, rab_dtype

_NO_FLOATS, _NO_WORDS = np.empty(0), np.empty(0, dtype=np.uint32)
for _empty in (_NO_FLOATS, _NO_WORDS):
    _empty.flags.writeable = False
_CLOUD_DTYPES: dict = {}


class Blobs:
    """The coloured blobs a camera sees this tick. Colours are kept as 0x00RRGGBB words when decoded
    from a cloud; ``colors`` (RGB rows) is derived on first use. Read-only by convention: ``of_color``
    returns this very object when every blob has that colour."""
    __slots__ = ("angles", "distances", "rgb", "_colors")

    def __init__(self, angles: np.ndarray, distances: np.ndarray, colors: Optional[np.ndarray] = None,
                 rgb: Optional[np.ndarray] = None):
        if colors is None and rgb is None:
            raise ValueError("Blobs needs colors ([m, 3] uint8) or rgb ([m] uint32)")
        self.angles = angles          # [m] rad, bearing relative to the heading, CCW
        self.distances = distances    # [m] planar distance from the robot centre, m
        self.rgb = rgb                # [m] uint32 0x00RRGGBB, or None
        self._colors = colors         # [m, 3] uint8 RGB, or None until asked for

    @property
    def colors(self) -> np.ndarray:
        """[m, 3] uint8 RGB."""
        if self._colors is None:
            colors = np.empty((len(self.rgb), 3), dtype=np.uint8)
            colors[:, 0], colors[:, 1], colors[:, 2] = self.rgb >> 16, self.rgb >> 8, self.rgb  # uint8 keeps the low byte
            self._colors = colors
        return self._colors

    def __len__(self) -> int:
        return len(self.angles)

    def of_color(self, rgb: Sequence[int]) -> "Blobs":
        if self.rgb is not None:
            r, g, b = (int(v) for v in rgb)
            keep = self.rgb == ((r << 16) | (g << 8) | b)
        else:
            keep = np.all(self.colors == np.asarray(rgb, dtype=np.uint8), axis=1)
        if keep.all():      # the common case in a swarm of one beacon colour: no copies
            return self
        return Blobs(self.angles[keep], self.distances[keep], None if self._colors is None else self._colors[keep],
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
    if len(points) == 0:
        return Blobs(_NO_FLOATS, _NO_FLOATS, rgb=_NO_WORDS)
    x = points["x"].astype(float)
    y = points["y"].astype(float)
    return Blobs(np.arctan2(y, x), np.hypot(x, y), rgb=points["rgb"] & 0xFFFFFF)


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


def decode_proximity_cdr(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Like decode_proximity, from the message's bytes."""
    return cdr.decode_scan(data)


def decode_light_cdr(data: bytes) -> np.ndarray:
    return cdr.decode_scan_intensities(data)


def decode_blobs_cdr(data: bytes, decoder: Optional[cdr.CloudDecoder] = None) -> Blobs:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr.CloudDecoder()).decode(data)
    return _blobs(np.frombuffer(points, dtype=_cloud_dtype(fields, point_step), count=width))


def decode_answer_cdr(data: bytes) -> tuple[int, float, float]:
    """TwistStamped cmd_vel bytes → (stamp ns, linear.x, angular.z)."""
    return (cdr.stamp_ns(data), *cdr.decode_twist(data))


def decode_unstamped_answer_cdr(data: bytes) -> tuple[float, float]:
    """Twist cmd_vel bytes → (linear.x, angular.z)."""
    return cdr.decode_unstamped_twist(data)


def decode_leds(msg: UInt8MultiArray, n_leds: int) -> np.ndarray:
    """→ [n_leds, 3] uint8; ValueError when the message does not carry n_leds colours."""
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size != 3 * n_leds:
        raise ValueError(f"leds message has {data.size} bytes, expected {3 * n_leds} ({n_leds} LEDs × RGB)")
    return data.reshape(n_leds, 3)


def decode_ground(msg: PointCloud2) -> np.ndarray:
    """→ [s] grey levels in [0, 1], in the model's sensor order."""
    return np.frombuffer(msg.data, dtype=GROUND_DTYPE, count=msg.width)["intensity"].astype(float)


def decode_scan(msg: LaserScan) -> np.ndarray:
    """→ [r] ranges in m from the scanner (±inf per REP-117)."""
    return np.frombuffer(msg.ranges, dtype=np.float32).astype(float)


def scan_angles(msg: LaserScan) -> np.ndarray:
    """[r] ray angles of a scan, rad in its frame."""
    return msg.angle_min + msg.angle_increment * np.arange(len(msg.ranges))


@dataclass(frozen=True)
class RabMessages:
    """The range-and-bearing messages one robot heard in a tick (one per sender, no sender id)."""
    ranges: np.ndarray      # [m] m, emitter to emitter
    bearings: np.ndarray    # [m] rad, horizontal, relative to the heading, CCW
    elevations: np.ndarray  # [m] rad, vertical bearing
    payloads: np.ndarray    # [m, B] uint8

    def __len__(self) -> int:
        return len(self.ranges)


def decode_rab(msg: PointCloud2) -> RabMessages:
    fields = {f.name: f for f in msg.fields}
    payload = fields.get("payload")
    if payload is None:
        raise ValueError("rab_rx message has no 'payload' field")
    points = np.frombuffer(msg.data, dtype=rab_dtype(payload.count), count=msg.width)
    return RabMessages(points["range"].astype(float), points["bearing"].astype(float),
                       points["elevation"].astype(float), points["payload"].copy())


def decode_rab_payload(msg: UInt8MultiArray, payload_bytes: int) -> np.ndarray:
    """→ [B] uint8; ValueError when the message does not carry exactly payload_bytes bytes."""
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size != payload_bytes:
        raise ValueError(f"rab_tx message has {data.size} bytes, expected {payload_bytes} "
                         f"(range_and_bearing.payload_bytes of the world file)")
    return data


def yaw_of(qz: float, qw: float) -> float:
    """Yaw of a planar quaternion (0, 0, qz, qw)."""
    return 2.0 * np.arctan2(qz, qw)


def decode_pose(msg: PoseStamped) -> np.ndarray:
    """→ [3] x, y (m), yaw (rad) in the world frame."""
    p, q = msg.pose.position, msg.pose.orientation
    return np.array([p.x, p.y, yaw_of(q.z, q.w)])


def decode_odometry(msg: Odometry) -> tuple[np.ndarray, np.ndarray]:
    """→ pose [3] x, y, yaw in odom; twist [2] linear (m/s), angular (rad/s) in base_link."""
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    return np.array([p.x, p.y, yaw_of(q.z, q.w)]), np.array([t.linear.x, t.angular.z])


def decode_wheels(msg: JointState, wheel_radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """→ (left, right) wheel speeds [2] m/s, and wheel travel since the start [2] m."""
    return (np.frombuffer(msg.velocity, dtype=np.float64) * wheel_radius_m,
            np.frombuffer(msg.position, dtype=np.float64) * wheel_radius_m)
