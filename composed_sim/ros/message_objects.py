"""Message objects built straight from a hosted publisher's CDR bytes, for the subscriptions of
the in-process links that take objects (a plain node's, ros/in_process.py).

``rclpy.serialization.deserialize_message`` converts the bytes into a C struct and that into the
Python object, twice as long as filling the object from the bytes with ``struct`` and ``array``
(docs/speed.md). LaserScan is what a plain node reads of
the simulator most (a LiDAR, a proximity or light ring): its builder here gives the very object
``deserialize_message`` gives (tests/ros/test_message_objects.py). Any other type, and bytes
that are not little-endian CDR (XCDR1, what rmw_fastrtps writes), go through rclpy.
"""
from __future__ import annotations

import struct
from array import array
from typing import Callable

from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan

from composed_sim.devices.common import cdr

_CDR_LE = b"\x00\x01"                  # the encapsulation header's representation id
_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_SCAN_METADATA = struct.Struct("<7f")   # angle_min … range_max


def _laser_scan(data: bytes) -> LaserScan:
    if data[:2] != _CDR_LE:
        return deserialize_message(data, LaserScan)
    msg = LaserScan()
    stamp = msg.header.stamp
    stamp.sec, stamp.nanosec = _STAMP.unpack_from(data, cdr.HEADER)
    frame_end = cdr.after_header(data)
    msg.header.frame_id = data[cdr.HEADER + 12:frame_end - 1].decode()     # without its NUL
    pos = cdr.align(frame_end, 4)
    (msg.angle_min, msg.angle_max, msg.angle_increment, msg.time_increment, msg.scan_time,
     msg.range_min, msg.range_max) = _SCAN_METADATA.unpack_from(data, pos)
    pos += _SCAN_METADATA.size
    (n,) = _U32.unpack_from(data, pos)
    msg.ranges = array("f", data[pos + 4:pos + 4 + 4 * n])
    pos += 4 + 4 * n
    (m,) = _U32.unpack_from(data, pos)
    msg.intensities = array("f", data[pos + 4:pos + 4 + 4 * m])
    return msg


_BUILDERS: dict[type, Callable[[bytes], object]] = {LaserScan: _laser_scan}


def builder(msg_type: type) -> Callable[[bytes], object]:
    """``msg_type``'s object from its CDR bytes."""
    return _BUILDERS.get(msg_type) or (lambda data: deserialize_message(data, msg_type))
