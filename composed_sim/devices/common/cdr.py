"""The contract's per-tick messages as serialized CDR bytes, written and read with numpy and struct.

rclpy publishes ``bytes`` as an already serialized message and takes messages as bytes when a
subscription is created with ``raw=True``. Both skip the conversion between Python message
objects and C structs, which is most of what a message costs in rclpy (docs/speed.md). The
bytes are the very CDR
that rclpy itself would produce: subscribers see ordinary typed messages, and the tests check
every codec against ``rclpy.serialization`` (tests/devices/test_cdr.py). ROS-free: each message's
template is written here (``Writer``), field by field in its type's order; the point clouds'
(templates, encoder, decoder) in cdr_clouds.py.

CDR (XCDR1, little endian): a 4-byte encapsulation header, then each primitive aligned to its
size counted from the end of that header; strings are a uint32 length (with the NUL) and the
bytes; sequences a uint32 count and the elements.
"""
from __future__ import annotations

import struct
from typing import Optional

import numpy as np

HEADER = 4                 # encapsulation header
_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_F64 = struct.Struct("<d")


def align(pos: int, size: int) -> int:
    """``pos`` (from the buffer's start) moved up to a multiple of ``size`` past the header."""
    return pos + (-(pos - HEADER) % size)


def after_header(data, pos: int = HEADER) -> int:
    """Position just after a std_msgs/Header starting at ``pos`` (stamp, then frame_id)."""
    (length,) = _U32.unpack_from(data, pos + 8)
    return pos + 12 + length


def stamp_ns(data) -> int:
    """A stamped message's header.stamp as integer nanoseconds (see contract.stamp_key)."""
    sec, nanosec = _STAMP.unpack_from(data, HEADER)
    return sec * 1_000_000_000 + nanosec


def stamp_bytes(sec: int, nanosec: int) -> bytes:
    """A header stamp as the 8 bytes that follow the encapsulation header."""
    return _STAMP.pack(sec, nanosec)


class Writer:
    """A message's CDR bytes, written field by field (each primitive aligned to its size)."""

    def __init__(self) -> None:
        self.buffer = bytearray(b"\x00\x01\x00\x00")        # encapsulation: CDR little endian

    def pad(self, size: int) -> "Writer":
        self.buffer.extend(bytes(-(len(self.buffer) - HEADER) % size))
        return self

    def put(self, fmt: str, *values) -> "Writer":
        """``values`` packed as ``fmt`` (one struct format letter, repeated), aligned to its size."""
        self.pad(struct.calcsize("<" + fmt.lstrip("0123456789")[0]))
        self.buffer.extend(struct.pack("<" + fmt, *values))
        return self

    def string(self, text: str) -> "Writer":
        data = text.encode() + b"\0"
        return self.put("I", len(data)).raw(data)

    def raw(self, data: bytes) -> "Writer":
        self.buffer.extend(data)
        return self

    def header(self, frame_id: str) -> "Writer":
        """A std_msgs/Header at stamp 0 (an encoder writes each message's stamp in)."""
        return self.put("iI", 0, 0).string(frame_id)

    def sequence(self, fmt: str, values) -> "Writer":
        """A sequence of one primitive: its count, then the elements (aligned even when empty,
        as Fast CDR does)."""
        self.put("I", len(values)).pad(struct.calcsize("<" + fmt))
        return self.raw(struct.pack(f"<{len(values)}{fmt}", *values))


def scan_bytes(frame_id: str, angle_min: float, angle_max: float, angle_increment: float, scan_time: float,
               range_min: float, range_max: float, n_ranges: int, n_intensities: int) -> bytes:
    """sensor_msgs/LaserScan with zero readings (time_increment 0: the rays are simultaneous)."""
    return bytes(Writer().header(frame_id)
                 .put("7f", angle_min, angle_max, angle_increment, 0.0, scan_time, range_min, range_max)
                 .sequence("f", [0.0] * n_ranges).sequence("f", [0.0] * n_intensities).buffer)


def ring_scan_bytes(frame_id: str, angles, range_max: float, n_ranges: int, n_intensities: int) -> bytes:
    """A LaserScan of a sensor ring: one ray per sensor at ``angles`` (evenly spaced)."""
    increment = float(angles[1] - angles[0]) if len(angles) > 1 else 0.0
    return scan_bytes(frame_id, float(angles[0]), float(angles[-1]), increment, 0.0, 0.0, range_max,
                      n_ranges, n_intensities)


def _pose(w: Writer) -> Writer:
    """geometry_msgs/Pose at the origin (quaternion w = 1, as ROS's default)."""
    return w.put("7d", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def pose_stamped_bytes(frame_id: str) -> bytes:
    return bytes(_pose(Writer().header(frame_id)).buffer)


def odometry_bytes(frame_id: str, child_frame_id: str) -> bytes:
    """nav_msgs/Odometry at rest, zero covariances."""
    w = _pose(Writer().header(frame_id).string(child_frame_id)).put("36d", *[0.0] * 36)
    return bytes(w.put("6d", *[0.0] * 6).put("36d", *[0.0] * 36).buffer)


def joint_state_bytes(frame_id: str, names, efforts) -> bytes:
    """sensor_msgs/JointState of ``names`` at position and velocity 0, with ``efforts``."""
    w = Writer().header(frame_id).put("I", len(names))
    for name in names:
        w.string(name)
    zeros = [0.0] * len(names)
    return bytes(w.sequence("d", zeros).sequence("d", zeros).sequence("d", list(efforts)).buffer)


def twist_stamped_bytes(frame_id: str = "") -> bytes:
    return bytes(Writer().header(frame_id).put("6d", *[0.0] * 6).buffer)


class UInt8ArrayEncoder:
    """A std_msgs/UInt8MultiArray of a fixed layout (``dims``: (label, size, stride) each, data
    offset 0): the bytes up to the data's count, once; a message is those, the count and the data."""

    def __init__(self, dims) -> None:
        writer = Writer().put("I", len(dims))
        for label, size, stride in dims:
            writer.string(label).put("2I", size, stride)
        self._head = bytes(writer.put("I", 0).buffer)          # then data_offset

    def encode(self, data: bytes) -> bytes:
        return b"".join((self._head, _U32.pack(len(data)), data))


def decode_uint8_array(data) -> np.ndarray:
    """std_msgs/UInt8MultiArray bytes → its data [n] uint8 (a view of ``data``), whatever its
    layout; ValueError for bytes that end before the message does."""
    try:
        pos = HEADER
        (n_dims,) = _U32.unpack_from(data, pos)
        pos += 4
        for _ in range(n_dims):                  # label (a string), size, stride
            (length,) = _U32.unpack_from(data, pos)
            pos = align(pos + 4 + length, 4) + 8
        (n,) = _U32.unpack_from(data, pos + 4)    # after data_offset
    except struct.error:
        raise ValueError(f"not a UInt8MultiArray: {len(data)} bytes end inside its layout") from None
    return np.frombuffer(data, dtype=np.uint8, count=n, offset=pos + 8)


class ScanEncoder:
    """One robot's LaserScan with fixed metadata and fixed-length arrays: the bytes of a template
    message cut around the stamp and the two arrays, so that a message is those pieces joined
    with the tick's stamp and the arrays' float32 bytes (one ``bytes.join``, no numpy per robot)."""

    def __init__(self, data: bytes) -> None:
        """``data``: the scan's template bytes (``scan_bytes``), its arrays at their lengths."""
        ranges_at = align(after_header(data), 4) + 7 * 4
        (n_ranges,) = _U32.unpack_from(data, ranges_at)
        ranges_at += 4
        (n_intensities,) = _U32.unpack_from(data, ranges_at + 4 * n_ranges)
        intensities_at = ranges_at + 4 * n_ranges + 4
        end = intensities_at + 4 * n_intensities
        self.ranges_bytes, self.intensities_bytes = 4 * n_ranges, 4 * n_intensities
        self._pieces = (data[:HEADER], data[HEADER + 8:ranges_at], data[ranges_at + 4 * n_ranges:intensities_at],
                        data[end:])

    def encode_bytes(self, stamp: bytes, ranges: bytes, intensities: bytes) -> bytes:
        """``stamp``: ``stamp_bytes``; ``ranges``, ``intensities``: the arrays as little-endian
        float32 bytes, of the lengths given at construction."""
        head, metadata, count, tail = self._pieces
        return b"".join((head, stamp, metadata, ranges, count, intensities, tail))

    def encode(self, sec: int, nanosec: int, intensities: np.ndarray,
               ranges: Optional[np.ndarray] = None) -> bytes:
        """The same from arrays (``ranges`` None: zeros)."""
        ranges_f4 = (np.zeros(self.ranges_bytes // 4, dtype="<f4") if ranges is None
                     else np.asarray(ranges, dtype="<f4")).tobytes()
        intensities_f4 = np.asarray(intensities, dtype="<f4").tobytes()
        if (len(ranges_f4), len(intensities_f4)) != (self.ranges_bytes, self.intensities_bytes):
            raise ValueError(f"this scan has {self.ranges_bytes // 4} ranges and {self.intensities_bytes // 4} "
                             f"intensities, got {len(ranges_f4) // 4} and {len(intensities_f4) // 4}")
        return self.encode_bytes(stamp_bytes(sec, nanosec), ranges_f4, intensities_f4)


def decode_scan(data) -> tuple[np.ndarray, np.ndarray]:
    """LaserScan bytes → (ranges [k], intensities [k]) as float64."""
    pos = align(after_header(data), 4) + 7 * 4
    (n,) = _U32.unpack_from(data, pos)
    ranges = np.frombuffer(data, dtype="<f4", count=n, offset=pos + 4)
    return ranges.astype(float), _intensities(data, pos + 4 + 4 * n)


def decode_scan_intensities(data) -> np.ndarray:
    """LaserScan bytes → intensities [k] as float64 (what a light ring carries)."""
    pos = align(after_header(data), 4) + 7 * 4
    (n,) = _U32.unpack_from(data, pos)
    return _intensities(data, pos + 4 + 4 * n)


def _intensities(data, pos: int) -> np.ndarray:
    (m,) = _U32.unpack_from(data, pos)
    return np.frombuffer(data, dtype="<f4", count=m, offset=pos + 4).astype(float)


class TwistEncoder:
    """TwistStamped with an empty frame_id; only linear.x and angular.z are set."""

    def __init__(self) -> None:
        self._buffer = bytearray(twist_stamped_bytes())
        self._linear_at = align(after_header(self._buffer), 8)
        self._angular_at = self._linear_at + 5 * 8               # angular.z, after linear x, y, z and angular x, y

    def encode(self, sec: int, nanosec: int, linear: float, angular: float) -> bytes:
        _STAMP.pack_into(self._buffer, HEADER, sec, nanosec)
        _F64.pack_into(self._buffer, self._linear_at, linear)
        _F64.pack_into(self._buffer, self._angular_at, angular)
        return bytes(self._buffer)


def decode_twist_stamped(data) -> tuple[int, float, float]:
    """TwistStamped bytes → (header.stamp ns, linear.x, angular.z)."""
    pos = align(after_header(data), 8)
    return stamp_ns(data), _F64.unpack_from(data, pos)[0], _F64.unpack_from(data, pos + 40)[0]


def decode_unstamped_twist(data) -> tuple[float, float]:
    """Twist bytes → (linear.x, angular.z): six float64 after the encapsulation header."""
    return _F64.unpack_from(data, HEADER)[0], _F64.unpack_from(data, HEADER + 40)[0]


_POSE = struct.Struct("<7d")


class FixedEncoder:
    """A message whose size never changes (its strings and sequence lengths are the template's):
    the template's bytes, with the stamp and the float64 fields at ``f64_at`` written in per
    message. ``pose_f64_at`` and the like say where a message type's fields are."""

    def __init__(self, template: bytes, f64_at) -> None:
        self._buffer = bytearray(template)
        self._f64_at = tuple(f64_at(self._buffer))

    def encode(self, stamp: bytes, *values: float) -> bytes:
        """``stamp``: ``stamp_bytes``; ``values``: one per offset of ``f64_at``, in its order."""
        buffer = self._buffer
        buffer[HEADER:HEADER + 8] = stamp
        for at, value in zip(self._f64_at, values):
            _F64.pack_into(buffer, at, value)
        return bytes(buffer)


def pose_f64_at(data) -> tuple[int, int, int, int, int]:
    """PoseStamped: where position.x, .y, .z, orientation.z and orientation.w are."""
    pose = align(after_header(data), 8)                   # position x y z, orientation x y z w
    return pose, pose + 8, pose + 16, pose + 40, pose + 48


def after_string(data, pos: int) -> int:
    """Position just after a string that starts at ``pos`` (or at the next multiple of 4)."""
    pos = align(pos, 4)
    (length,) = _U32.unpack_from(data, pos)
    return pos + 4 + length


def odometry_f64_at(data) -> tuple[int, ...]:
    """Odometry: where pose.position.x, .y, pose.orientation.z, .w, twist.linear.x and
    twist.angular.z are (after the header and child_frame_id; each of the pose and the twist is
    followed by its 36-entry covariance)."""
    pose = align(after_string(data, after_header(data)), 8)
    twist = pose + (7 + 36) * 8
    return pose, pose + 8, pose + 40, pose + 48, twist, twist + 40


def decode_odometry(data) -> tuple[float, ...]:
    """Odometry bytes → (x, y, qz, qw, linear.x, angular.z)."""
    at = odometry_f64_at(data)
    return tuple(_F64.unpack_from(data, pos)[0] for pos in at)


def joint_state_f64_at(data) -> tuple[list[int], list[int]]:
    """JointState: where each joint's position and velocity are (after the names)."""
    pos = align(after_header(data), 4)
    (n,) = _U32.unpack_from(data, pos)
    pos += 4
    for _ in range(n):
        pos = after_string(data, pos)
    arrays = []
    for _ in range(2):                                    # position, velocity (then effort)
        pos = align(pos, 4)
        (count,) = _U32.unpack_from(data, pos)
        start = align(pos + 4, 8)                         # Fast CDR aligns an empty sequence's too
        arrays.append([start + 8 * k for k in range(count)])
        pos = start + 8 * count
    return arrays[0], arrays[1]


def decode_joint_state(data) -> tuple[np.ndarray, np.ndarray]:
    """JointState bytes → (positions [j], velocities [j]) as float64."""
    positions, velocities = joint_state_f64_at(data)
    return tuple(np.array([_F64.unpack_from(data, pos)[0] for pos in at]) for at in (positions, velocities))


def decode_pose(data) -> tuple[float, float, float, float]:
    """PoseStamped bytes → (x, y, qz, qw)."""
    x, y, _, _, _, qz, qw = _POSE.unpack_from(data, align(after_header(data), 8))
    return x, y, qz, qw


class TransformsEncoder:
    """``tf2_msgs/msg/TFMessage`` bytes for a fixed list of (parent, child) frames: the frame
    names are laid out once; each message then only writes the stamps and the poses."""

    def __init__(self, frames) -> None:
        w = Writer().put("I", len(frames))
        self._stamps, self._poses = [], []
        for parent, child in frames:                     # geometry_msgs/TransformStamped
            w.pad(4)
            self._stamps.append(len(w.buffer))
            w.put("iI", 0, 0).string(parent).string(child).pad(8)
            self._poses.append(len(w.buffer))            # translation x y z, rotation x y z w
            w.raw(bytes(_POSE.size))
        self._buffer = w.buffer

    def encode(self, sec: int, nanosec: int, poses) -> bytes:
        """``poses``: per frame pair (x, y, z, qx, qy, qz, qw)."""
        for at in self._stamps:
            _STAMP.pack_into(self._buffer, at, sec, nanosec)
        for at, pose in zip(self._poses, poses):
            _POSE.pack_into(self._buffer, at, *pose)
        return bytes(self._buffer)
