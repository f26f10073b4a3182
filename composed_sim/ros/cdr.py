"""The contract's per-tick messages as serialized CDR bytes, written and read with numpy and struct.

rclpy publishes ``bytes`` as an already serialized message and takes messages as bytes when a
subscription is created with ``raw=True``. Both skip the conversion between Python message
objects and C structs, which is most of what a message costs in rclpy (measured here: a
LaserScan published and taken as objects 20 µs, as bytes 5 µs). The bytes are the very CDR
that rclpy itself would produce: subscribers see ordinary typed messages, and the tests check
every codec against ``rclpy.serialization`` byte for byte.

CDR (XCDR1, little endian): a 4-byte encapsulation header, then each primitive aligned to its
size counted from the end of that header; strings are a uint32 length (with the NUL) and the
bytes; sequences a uint32 count and the elements.
"""
from __future__ import annotations

import struct
from typing import Optional

import numpy as np
from rclpy.serialization import serialize_message

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


class ScanEncoder:
    """One robot's LaserScan with fixed metadata and fixed-length arrays: each call writes the
    stamp and the arrays into the bytes of a template message."""

    def __init__(self, template, n_ranges: int, n_intensities: int) -> None:
        template.ranges = [0.0] * n_ranges
        template.intensities = [0.0] * n_intensities
        self._buffer = bytearray(serialize_message(template))
        pos = align(after_header(self._buffer), 4) + 7 * 4          # angle_min … range_max
        self._stamp = np.frombuffer(self._buffer, dtype="<u4", count=2, offset=HEADER)
        self._ranges = np.frombuffer(self._buffer, dtype="<f4", count=n_ranges, offset=pos + 4)
        pos += 4 + 4 * n_ranges
        self._intensities = np.frombuffer(self._buffer, dtype="<f4", count=n_intensities, offset=pos + 4)

    def encode(self, sec: int, nanosec: int, intensities: np.ndarray,
               ranges: Optional[np.ndarray] = None) -> bytes:
        self._stamp[0], self._stamp[1] = sec, nanosec
        if ranges is not None:
            self._ranges[:] = ranges
        self._intensities[:] = intensities
        return bytes(self._buffer)


def decode_scan(data) -> tuple[np.ndarray, np.ndarray]:
    """LaserScan bytes → (ranges [k], intensities [k]) as float64."""
    pos = align(after_header(data), 4) + 7 * 4
    (n,) = _U32.unpack_from(data, pos)
    ranges = np.frombuffer(data, dtype="<f4", count=n, offset=pos + 4)
    pos += 4 + 4 * n
    (m,) = _U32.unpack_from(data, pos)
    intensities = np.frombuffer(data, dtype="<f4", count=m, offset=pos + 4)
    return ranges.astype(float), intensities.astype(float)


class CloudEncoder:
    """One robot's PointCloud2 of fixed fields (one row, ``width`` points): the template's bytes
    up to its data, with the stamp, width and row_step written in, then the points."""

    def __init__(self, template) -> None:
        template.width, template.row_step, template.data = 0, 0, b""
        data = serialize_message(template)
        self._point_step = template.point_step
        self._dense = data[-1:]                               # is_dense, after the empty data
        self._head = bytearray(data[:-5])                     # up to the data's length field
        self._stamp = np.frombuffer(self._head, dtype="<u4", count=2, offset=HEADER)
        self._width_at = align(after_header(self._head), 4) + 4          # after height
        self._row_step_at = len(self._head) - 4

    def encode(self, sec: int, nanosec: int, points: bytes, width: int) -> bytes:
        self._stamp[0], self._stamp[1] = sec, nanosec
        _U32.pack_into(self._head, self._width_at, width)
        _U32.pack_into(self._head, self._row_step_at, width * self._point_step)
        return b"".join((self._head, _U32.pack(len(points)), points, self._dense))


def decode_cloud(data) -> tuple[int, tuple[tuple[str, int, int], ...], int, memoryview]:
    """PointCloud2 bytes → (width, ((field name, offset, datatype), …), point_step, data)."""
    pos = align(after_header(data), 4)
    _height, width, n_fields = struct.unpack_from("<III", data, pos)
    pos += 12
    fields = []
    for _ in range(n_fields):
        (length,) = _U32.unpack_from(data, pos)
        name = bytes(data[pos + 4:pos + 3 + length]).decode()
        pos = align(pos + 4 + length, 4)
        offset, datatype = _U32.unpack_from(data, pos)[0], data[pos + 4]
        pos = align(pos + 5, 4) + 4                              # count
        fields.append((name, offset, datatype))
    pos = align(pos + 1, 4)                                      # is_bigendian
    point_step, _row_step, size = struct.unpack_from("<III", data, pos)
    pos += 12
    return width, tuple(fields), point_step, memoryview(data)[pos:pos + size]


class TwistEncoder:
    """TwistStamped with an empty frame_id; only linear.x and angular.z are set."""

    def __init__(self, template) -> None:
        self._buffer = bytearray(serialize_message(template))
        self._linear_at = align(after_header(self._buffer), 8)
        self._angular_at = self._linear_at + 5 * 8               # angular.z, after linear x, y, z and angular x, y

    def encode(self, sec: int, nanosec: int, linear: float, angular: float) -> bytes:
        _STAMP.pack_into(self._buffer, HEADER, sec, nanosec)
        _F64.pack_into(self._buffer, self._linear_at, linear)
        _F64.pack_into(self._buffer, self._angular_at, angular)
        return bytes(self._buffer)


def decode_twist(data) -> tuple[float, float]:
    """TwistStamped bytes → (linear.x, angular.z)."""
    pos = align(after_header(data), 8)
    return _F64.unpack_from(data, pos)[0], _F64.unpack_from(data, pos + 40)[0]
