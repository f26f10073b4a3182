"""Live markers for RViz and Foxglove: the whole swarm in one ``visualization_msgs/MarkerArray``.

Published on ``/swarm/markers`` (optional). Two markers, whatever the swarm size, so a viewer
handles 1280 robots as two draw calls rather than 1280 markers:

  ns "swarm_bodies",   id 0, SPHERE_LIST: one flattened sphere per robot (diameter = body
                       diameter, height = body height), coloured per point by its display LED
                       colour (``composed_sim.world.robot_models.display_colors``; robots with no LED lit
                       get ``DEFAULT_COLOR``)
  ns "swarm_headings", id 1, LINE_LIST: one segment per robot from its centre to 1.5 body
                       radii ahead, black

Frame ``world`` (``composed_sim.recording.FRAME_ID``), the same fixed frame as the recorded
``/swarm/state``: the simulator's planar world frame, z up, origin at the world's (0, 0). Set it
as the fixed frame in RViz/Foxglove. Markers never expire (lifetime 0): each message replaces the
previous one (same ns and id).

Building the message object costs about 12 ms at 1280 robots (one rclpy Point and ColorRGBA
object per robot) plus 5 ms to serialise it; ``swarm_markers_cdr`` writes the same message's CDR
bytes straight from the arrays in about 0.3 ms. ``Publisher.publish`` accepts those bytes as
they are (``publish_raw``), and so does ``BagRecorder.write_serialized``. A test checks that the
bytes deserialise to a message equal to ``swarm_markers``'s (only CDR padding bytes, which
rmw leaves unset, can differ).
"""
from __future__ import annotations

import struct
from typing import Optional, Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from composed_sim.world.robot_models import display_colors
from composed_sim.ros.contract import SWARM_MARKERS_TOPIC
from composed_sim.ros.contract import WORLD_FRAME as FRAME_ID

MARKERS_TOPIC = SWARM_MARKERS_TOPIC
MARKERS_TYPE = "visualization_msgs/msg/MarkerArray"
DEFAULT_COLOR = (0.12, 0.47, 0.71)      # matplotlib's tab:blue, for robots with every LED off
HEADING_LENGTH = 1.5                    # heading segment length in body radii


def swarm_markers(names: Sequence[str], positions: np.ndarray, headings: np.ndarray,
                  led_colors: Optional[np.ndarray], radius: float, stamp: Time, *,
                  height: Optional[float] = None, frame_id: str = FRAME_ID) -> MarkerArray:
    """The swarm as one MarkerArray: bodies (SPHERE_LIST) and headings (LINE_LIST).

    names: [n] (only checked against n; the points follow this order). positions [n, 2] m,
    headings [n] rad, led_colors [n, L, 3] or [n, 3] uint8 or None (all DEFAULT_COLOR),
    radius: body radius m, height: body height m (default: the diameter), stamp: sim time.
    """
    g = _geometry(names, positions, headings, led_colors, radius, height)
    bodies = _marker(0, "swarm_bodies", Marker.SPHERE_LIST, stamp, frame_id)
    bodies.scale.x, bodies.scale.y, bodies.scale.z = g.body_scale
    bodies.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)   # per-point colours override it
    # One tolist() per array: building Points from Python floats is the cost here.
    bodies.points = [Point(x=x, y=y, z=z) for x, y, z in g.body_points.tolist()]
    bodies.colors = [ColorRGBA(r=r, g=g_, b=b, a=a) for r, g_, b, a in g.body_colors.tolist()]

    arrows = _marker(1, "swarm_headings", Marker.LINE_LIST, stamp, frame_id)
    arrows.scale.x = g.line_width
    arrows.color = ColorRGBA(r=0.0, g=0.0, b=0.0, a=1.0)
    arrows.points = [Point(x=x, y=y, z=z) for x, y, z in g.line_points.tolist()]

    out = MarkerArray()
    out.markers = [bodies, arrows]
    return out


def swarm_markers_cdr(names: Sequence[str], positions: np.ndarray, headings: np.ndarray,
                      led_colors: Optional[np.ndarray], radius: float, stamp: Time, *,
                      height: Optional[float] = None, frame_id: str = FRAME_ID) -> bytes:
    """``swarm_markers(...)`` serialised (CDR, little-endian), built from the arrays directly."""
    g = _geometry(names, positions, headings, led_colors, radius, height)
    w = _CdrWriter()
    w.u32(2)                                   # MarkerArray.markers: 2 markers
    _write_marker(w, 0, "swarm_bodies", Marker.SPHERE_LIST, stamp, frame_id, g.body_scale,
                  (1.0, 1.0, 1.0, 1.0), g.body_points, g.body_colors)
    _write_marker(w, 1, "swarm_headings", Marker.LINE_LIST, stamp, frame_id,
                  (g.line_width, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), g.line_points, None)
    return w.bytes()


class _Geometry:
    """The arrays both builders share."""

    def __init__(self, body_scale, body_points, body_colors, line_width, line_points):
        self.body_scale = body_scale        # (x, y, z) m
        self.body_points = body_points      # [n, 3] float64
        self.body_colors = body_colors      # [n, 4] float32 RGBA in [0, 1]
        self.line_width = line_width        # m
        self.line_points = line_points      # [2n, 3] float64: centre, tip, centre, tip, ...


def _geometry(names, positions, headings, led_colors, radius, height) -> _Geometry:
    n = len(names)
    p = np.asarray(positions, dtype=float)
    h = np.asarray(headings, dtype=float)
    if p.shape != (n, 2):
        raise ValueError(f"positions must be [{n}, 2] for {n} names, got shape {p.shape}")
    if h.shape != (n,):
        raise ValueError(f"headings must be [{n}], got shape {h.shape}")
    if not radius > 0:
        raise ValueError(f"radius must be > 0 m (got {radius})")
    radius = float(radius)
    height = 2 * radius if height is None else float(height)

    # float32 like ColorRGBA's fields, so that both builders give the same numbers.
    rgba = np.empty((n, 4), dtype=np.float32)
    rgba[:, :3] = DEFAULT_COLOR
    rgba[:, 3] = 1.0
    if led_colors is not None:
        colors = display_colors(led_colors)
        if colors.shape != (n, 3):
            raise ValueError(f"led_colors must hold {n} robots, got shape {np.shape(led_colors)}")
        lit = colors.any(axis=1)
        rgba[lit, :3] = colors[lit] / np.float32(255.0)

    bodies = np.empty((n, 3))
    bodies[:, :2] = p
    bodies[:, 2] = height / 2
    tips = p + HEADING_LENGTH * radius * np.stack([np.cos(h), np.sin(h)], axis=1)
    lines = np.empty((n, 2, 3))
    lines[:, 0, :2], lines[:, 1, :2] = p, tips
    lines[:, :, 2] = height + 0.01                  # above the bodies, so always visible
    return _Geometry((2 * radius, 2 * radius, height), bodies, rgba, 0.25 * radius,
                     lines.reshape(-1, 3))


class _CdrWriter:
    """Little-endian CDR (XCDR1, as rmw_fastrtps writes it): each primitive aligned to its size
    (at most 8) from the start of the payload, after the 4-byte encapsulation header."""

    def __init__(self):
        self.buf = bytearray(b"\x00\x01\x00\x00")

    def align(self, size: int) -> None:
        self.buf += bytes(-(len(self.buf) - 4) % size)

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += struct.pack("<I", value)

    def i32(self, value: int) -> None:
        self.align(4)
        self.buf += struct.pack("<i", value)

    def f64s(self, *values: float) -> None:
        self.align(8)
        self.buf += struct.pack(f"<{len(values)}d", *values)

    def f32s(self, *values: float) -> None:
        self.align(4)
        self.buf += struct.pack(f"<{len(values)}f", *values)

    def boolean(self, value: bool) -> None:
        self.buf.append(1 if value else 0)

    def string(self, text: str) -> None:
        data = text.encode() + b"\x00"
        self.u32(len(data))
        self.buf += data

    def block(self, array: np.ndarray, align: int) -> None:
        """A sequence's elements as one contiguous little-endian array (count written before)."""
        if array.size:
            self.align(align)
            self.buf += np.ascontiguousarray(array).tobytes()

    def bytes(self) -> bytes:
        return bytes(self.buf)


def _write_marker(w: _CdrWriter, marker_id: int, ns: str, kind: int, stamp: Time, frame_id: str,
                  scale, color, points: np.ndarray, colors: Optional[np.ndarray]) -> None:
    # Field order of visualization_msgs/msg/Marker (ROS 2 Jazzy).
    w.i32(stamp.sec)
    w.u32(stamp.nanosec)
    w.string(frame_id)
    w.string(ns)
    w.i32(marker_id)
    w.i32(kind)
    w.i32(Marker.ADD)
    w.f64s(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)          # pose: origin, identity orientation
    w.f64s(*scale)
    w.f32s(*color)
    w.i32(0)                                              # lifetime: 0 = forever
    w.u32(0)
    w.boolean(False)                                      # frame_locked
    w.u32(len(points))
    w.block(points.astype("<f8", copy=False), 8)
    if colors is None:
        w.u32(0)
    else:
        w.u32(len(colors))
        w.block(colors.astype("<f4", copy=False), 4)
    w.string("")                                          # texture_resource
    w.i32(0)                                              # texture (CompressedImage): stamp,
    w.u32(0)
    w.string("")                                          # frame_id,
    w.string("")                                          # format,
    w.u32(0)                                              # data[]
    w.u32(0)                                              # uv_coordinates[]
    w.string("")                                          # text
    w.string("")                                          # mesh_resource
    w.string("")                                          # mesh_file: filename,
    w.u32(0)                                              # data[]
    w.boolean(False)                                      # mesh_use_embedded_materials


def _marker(marker_id: int, ns: str, kind: int, stamp: Time, frame_id: str) -> Marker:
    m = Marker()
    m.header.stamp = stamp
    m.header.frame_id = frame_id
    m.ns = ns
    m.id = marker_id
    m.type = kind
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.lifetime = Duration(sec=0, nanosec=0)
    m.frame_locked = False
    return m
