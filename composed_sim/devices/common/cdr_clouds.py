"""sensor_msgs/PointCloud2 as serialized CDR bytes (cdr.py: the format, its primitives and the other
messages): a template of the cloud's fields written once, an encoder that joins it with each tick's
stamp and points, and a decoder that parses a stream's layout once and then only checks it.

A cloud here is one row (height 1) of ``width`` points laid out as a numpy structured dtype, dense,
little endian; its fields are that dtype's (name, offset, PointField datatype, count).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Optional

import numpy as np

from composed_sim.devices.common.cdr import HEADER, Writer, after_header, align, stamp_bytes

_U32 = struct.Struct("<I")
_TWO_U32 = struct.Struct("<II")


# sensor_msgs/PointField datatypes.
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_POINT_FIELD_TYPES = {np.dtype("<f4"): FLOAT32, np.dtype("<u4"): UINT32, np.dtype("u1"): UINT8}


def point_fields(dtype: np.dtype) -> tuple[tuple[str, int, int, int], ...]:
    """A PointCloud2's fields (name, offset, datatype, count) for points laid out as ``dtype``
    (an array field: its count)."""
    fields = []
    for name in dtype.names:
        field_type, offset = dtype.fields[name][:2]
        fields.append((name, offset, _POINT_FIELD_TYPES[field_type.base], int(np.prod(field_type.shape, dtype=int))))
    return tuple(fields)


def cloud_bytes(frame_id: str, dtype: np.dtype, width: int = 0) -> bytes:
    """sensor_msgs/PointCloud2, one row of ``width`` zero points laid out as ``dtype``, dense."""
    w = Writer().header(frame_id).put("II", 1, width)
    fields = point_fields(dtype)
    w.put("I", len(fields))
    for name, offset, datatype, count in fields:
        w.string(name).put("I", offset).put("B", datatype).put("I", count)
    return bytes(w.put("?", False).put("II", dtype.itemsize, dtype.itemsize * width)
                 .sequence("B", bytes(dtype.itemsize * width)).put("?", True).buffer)


class CloudEncoder:
    """One robot's PointCloud2 of fixed fields (one row, ``width`` points): the template's bytes
    up to its data, in pieces around the stamp, width and row_step, then the points."""

    def __init__(self, data: bytes) -> None:
        """``data``: the cloud's template bytes without points (``cloud_bytes``)."""
        self._point_step = cloud_layout(data).point_step
        head = data[:-5]                                      # up to the data's length field
        width_at = align(after_header(head), 4) + 4           # after height
        row_step_at = len(head) - 4
        self._pieces = (head[:HEADER], head[HEADER + 8:width_at], head[width_at + 4:row_step_at],
                        data[-1:])                            # is_dense, after the empty data

    def encode_bytes(self, stamp: bytes, points: bytes, width: int) -> bytes:
        """``stamp``: ``stamp_bytes``; ``points``: ``width`` points' bytes."""
        head, height, layout, dense = self._pieces
        return b"".join((head, stamp, height, _U32.pack(width), layout,
                         _TWO_U32.pack(width * self._point_step, len(points)), points, dense))

    def encode(self, sec: int, nanosec: int, points: bytes, width: int) -> bytes:
        return self.encode_bytes(stamp_bytes(sec, nanosec), points, width)


@dataclass(frozen=True)
class CloudLayout:
    """Where a PointCloud2's per-message fields are, and its point layout."""
    width_at: int                                  # byte offset of width
    row_step_at: int                               # … of row_step (then the data's length, the data)
    fields: tuple[tuple[str, int, int], ...]       # (name, offset, datatype) per field
    point_step: int


def cloud_layout(data) -> CloudLayout:
    pos = align(after_header(data), 4)
    (n_fields,) = _U32.unpack_from(data, pos + 8)                # after height and width
    width_at = pos + 4
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
    (point_step,) = _U32.unpack_from(data, pos)
    return CloudLayout(width_at, pos + 4, tuple(fields), point_step)


class CloudDecoder:
    """PointCloud2 bytes → (width, ((field name, offset, datatype), …), point_step, data), for one
    stream of clouds: the layout is parsed from the first message and, on the next ones, only
    checked byte for byte (frame_id and height before the width; the fields and point_step
    between width and row_step), so parsing happens again only when the publisher changes it."""

    def __init__(self) -> None:
        self._layout: Optional[CloudLayout] = None
        self._before_width = self._before_row_step = b""

    def decode(self, data) -> tuple[int, tuple[tuple[str, int, int], ...], int, memoryview]:
        layout = self._layout
        if (layout is None or data[HEADER + 8:layout.width_at] != self._before_width
                or data[layout.width_at + 4:layout.row_step_at] != self._before_row_step):
            layout = self._layout = cloud_layout(data)
            self._before_width = bytes(data[HEADER + 8:layout.width_at])
            self._before_row_step = bytes(data[layout.width_at + 4:layout.row_step_at])
        (width,) = _U32.unpack_from(data, layout.width_at)
        _row_step, size = _TWO_U32.unpack_from(data, layout.row_step_at)
        start = layout.row_step_at + 8
        return width, layout.fields, layout.point_step, memoryview(data)[start:start + size]


def decode_cloud(data) -> tuple[int, tuple[tuple[str, int, int], ...], int, memoryview]:
    """PointCloud2 bytes → (width, ((field name, offset, datatype), …), point_step, data)."""
    return CloudDecoder().decode(data)
