"""Live markers for RViz and Foxglove: the whole swarm in one ``visualization_msgs/MarkerArray``.

Published on ``/swarm/markers`` (optional) and served as the Foxglove scene (tools layer,
``composed_sim/live/foxglove_server.py``). One marker per robot size plus one, whatever the swarm size,
so a viewer handles 1280 robots as two or three draw calls rather than 1280 markers:

  ns "swarm_bodies",   id k, SPHERE_LIST: one flattened sphere per robot of the k-th distinct
                       (radius, height) in the swarm (diameter = body diameter, height = body
                       height: each robot sized by its own model), coloured per point by its display
                       LED colour (``composed_sim.world.robot_models.display_colors``; robots with
                       no LED lit get ``DEFAULT_COLOR``)
  ns "swarm_headings", id 1, LINE_LIST: one segment per robot from its centre to 1.5 of its body
                       radii ahead, black
  ns "world",          id 0 …, the static world when given (``world_shapes``): walls and boxes
                       (CUBE), cylinders (CYLINDER), lights (SPHERE in their colour), floor shapes
                       (flat CYLINDER / CUBE at z = 0). They are sent with every message, so a
                       viewer that attaches late sees them too.

Frame ``world`` (``composed_sim.outputs.recording.FRAME_ID``), the same fixed frame as the recorded
``/swarm/state``: the simulator's planar world frame, z up, origin at the world's (0, 0). Set it
as the fixed frame in RViz/Foxglove. Markers never expire (lifetime 0): each message replaces the
previous one (same ns and id).

Building the message object (one rclpy Point and ColorRGBA object per robot) and serialising it
cost milliseconds a tick at 1280 robots; ``swarm_markers_cdr`` writes the same message's CDR bytes
straight from the arrays, for a fraction of that (docs/speed.md). ``Publisher.publish`` accepts those bytes as
they are (``publish_raw``), and so does ``BagRecorder.write_serialized``. A test checks that the
bytes deserialise to a message equal to ``swarm_markers``'s (only CDR padding bytes, which
rmw leaves unset, can differ).
"""
from __future__ import annotations

import struct
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional, Sequence, Union

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from composed_sim.core.scene import static_scene
from composed_sim.devices.common.poses import checked_poses
from composed_sim.world.robot_models import display_colors
from composed_sim.ros.contract import SWARM_MARKERS_TOPIC
from composed_sim.ros.contract import WORLD_FRAME as FRAME_ID

if TYPE_CHECKING:
    from composed_sim.world.schema import World

MARKERS_TOPIC = SWARM_MARKERS_TOPIC
MARKERS_TYPE = "visualization_msgs/msg/MarkerArray"
DEFAULT_COLOR = (0.12, 0.47, 0.71)      # matplotlib's tab:blue, for robots with every LED off
HEADING_LENGTH = 1.5                    # heading segment length in body radii


Sizes = Union[float, np.ndarray]    # one value for every robot, or [n]: one per robot


@dataclass(frozen=True)
class Shape:
    """One static marker of the world: a CUBE, CYLINDER or SPHERE at a planar pose."""
    marker_id: int
    kind: int                               # Marker.CUBE, CYLINDER or SPHERE
    pose: tuple[float, float, float, float]  # x, y, z (centre) m, yaw rad
    scale: tuple[float, float, float]        # m
    color: tuple[float, float, float, float]  # RGBA in [0, 1]


def world_shapes(world: "World") -> list[Shape]:
    """The world's static parts as markers (ns "world"): floor shapes, walls and fixed boxes,
    fixed cylinders, lights. Movable objects are not drawn (they move: the scene would lie)."""
    out: list[Shape] = []

    def add(kind, pose, scale, color):
        out.append(Shape(len(out), kind, tuple(map(float, pose)), tuple(map(float, scale)),
                         tuple(map(float, color))))

    floor_z = 0.001
    for shape in world.floor.shapes if world.floor is not None else ():
        rgba = (*(c / 255 for c in shape.color), 1.0)
        if shape.type == "circle":
            add(Marker.CYLINDER, (*shape.position, floor_z / 2, 0.0),
                (2 * shape.radius_m, 2 * shape.radius_m, floor_z), rgba)
        else:
            add(Marker.CUBE, (*shape.position, floor_z / 2, shape.yaw_rad), (*shape.size, floor_z), rgba)
    grey = (0.55, 0.55, 0.55, 1.0)
    scene = static_scene(world)
    for corners, height in zip(scene.box_corners, scene.box_heights):
        centre = corners.mean(axis=0)
        along, across = corners[1] - corners[0], corners[3] - corners[0]
        add(Marker.CUBE, (*centre, height / 2, math.atan2(along[1], along[0])),
            (np.hypot(*along), np.hypot(*across), height), grey)
    for centre, r, height in zip(scene.cyl_centres, scene.cyl_radii, scene.cyl_heights):
        add(Marker.CYLINDER, (*centre, height / 2, 0.0), (2 * r, 2 * r, height), grey)
    for light in world.lights:
        add(Marker.SPHERE, (*light.position, light.height_m, 0.0), (0.08, 0.08, 0.08),
            (*(c / 255 for c in light.color), 1.0))
    return out


def swarm_markers(names: Sequence[str], positions: np.ndarray, headings: np.ndarray,
                  led_colors: Optional[np.ndarray], radius: Sizes, stamp: Time, *,
                  height: Optional[Sizes] = None, frame_id: str = FRAME_ID,
                  shapes: Sequence[Shape] = ()) -> MarkerArray:
    """The swarm as one MarkerArray: bodies (one SPHERE_LIST per robot size), headings
    (LINE_LIST), then the world's static ``shapes``.

    names: [n] (only checked against n; the points follow this order). positions [n, 2] m,
    headings [n] rad, led_colors [n, L, 3] or [n, 3] uint8 or None (all DEFAULT_COLOR),
    radius: body radius m, height: body height m (default: the diameter), each a number or [n]
    (``Simulation.radii``, ``Simulation.heights``), stamp: sim time.
    """
    g = _geometry(names, positions, headings, led_colors, radius, height)
    out = MarkerArray()
    for k, (scale, members) in enumerate(g.body_groups):
        bodies = _marker(k, "swarm_bodies", Marker.SPHERE_LIST, stamp, frame_id)
        bodies.scale.x, bodies.scale.y, bodies.scale.z = scale
        bodies.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)   # per-point colours override it
        # One tolist() per array: building Points from Python floats is the cost here.
        bodies.points = [Point(x=x, y=y, z=z) for x, y, z in g.body_points[members].tolist()]
        bodies.colors = [ColorRGBA(r=r, g=g_, b=b, a=a) for r, g_, b, a in g.body_colors[members].tolist()]
        out.markers.append(bodies)

    arrows = _marker(1, "swarm_headings", Marker.LINE_LIST, stamp, frame_id)
    arrows.scale.x = g.line_width
    arrows.color = ColorRGBA(r=0.0, g=0.0, b=0.0, a=1.0)
    arrows.points = [Point(x=x, y=y, z=z) for x, y, z in g.line_points.tolist()]
    out.markers.append(arrows)
    for shape in shapes:
        m = _marker(shape.marker_id, "world", shape.kind, stamp, frame_id)
        m.pose = _pose(*shape.pose)
        m.scale.x, m.scale.y, m.scale.z = shape.scale
        m.color = ColorRGBA(r=shape.color[0], g=shape.color[1], b=shape.color[2], a=shape.color[3])
        out.markers.append(m)
    return out


def swarm_markers_cdr(names: Sequence[str], positions: np.ndarray, headings: np.ndarray,
                      led_colors: Optional[np.ndarray], radius: Sizes, stamp: Time, *,
                      height: Optional[Sizes] = None, frame_id: str = FRAME_ID,
                      shapes: Sequence[Shape] = ()) -> bytes:
    """``swarm_markers(...)`` serialised (CDR, little-endian), built from the arrays directly."""
    g = _geometry(names, positions, headings, led_colors, radius, height)
    w = _CdrWriter()
    w.u32(len(g.body_groups) + 1 + len(shapes))     # MarkerArray.markers
    identity = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    for k, (scale, members) in enumerate(g.body_groups):
        _write_marker(w, k, "swarm_bodies", Marker.SPHERE_LIST, stamp, frame_id, identity, scale,
                      (1.0, 1.0, 1.0, 1.0), g.body_points[members], g.body_colors[members])
    _write_marker(w, 1, "swarm_headings", Marker.LINE_LIST, stamp, frame_id, identity,
                  (g.line_width, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), g.line_points, None)
    for shape in shapes:
        x, y, z, yaw = shape.pose
        pose = (x, y, z, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        _write_marker(w, shape.marker_id, "world", shape.kind, stamp, frame_id, pose, shape.scale,
                      shape.color, _NO_POINTS, None)
    return w.bytes()


_NO_POINTS = np.zeros((0, 3))


def _pose(x: float, y: float, z: float, yaw: float) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = x, y, z
    pose.orientation.z, pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return pose


class _Geometry:
    """The arrays both builders share."""

    def __init__(self, body_groups, body_points, body_colors, line_width, line_points):
        self.body_groups = body_groups      # [(scale (x, y, z) m, robot indices)] one per size
        self.body_points = body_points      # [n, 3] float64
        self.body_colors = body_colors      # [n, 4] float32 RGBA in [0, 1]
        self.line_width = line_width        # m
        self.line_points = line_points      # [2n, 3] float64: centre, tip, centre, tip, ...


def _geometry(names, positions, headings, led_colors, radius, height) -> _Geometry:
    n = len(names)
    p, h = checked_poses(n, positions, headings)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), (n,))
    if not np.all(radius > 0):
        raise ValueError(f"radius must be > 0 m (got {radius.min()})")
    height = 2 * radius if height is None else np.broadcast_to(np.asarray(height, dtype=float), (n,))

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
    tips = p + (HEADING_LENGTH * radius)[:, None] * np.stack([np.cos(h), np.sin(h)], axis=1)
    lines = np.empty((n, 2, 3))
    lines[:, 0, :2], lines[:, 1, :2] = p, tips
    lines[:, :, 2] = (height + 0.01)[:, None]        # above the bodies, so always visible
    # One SPHERE_LIST per distinct size (a marker has one scale); a homogeneous swarm has one.
    sizes, which = np.unique(np.stack([radius, height], axis=1), axis=0, return_inverse=True)
    groups = [((2 * r, 2 * r, z), np.flatnonzero(which.ravel() == k)) for k, (r, z) in enumerate(sizes.tolist())]
    line_width = 0.25 * float(radius.min()) if n else 0.02
    return _Geometry(groups, bodies, rgba, line_width, lines.reshape(-1, 3))


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
                  pose, scale, color, points: np.ndarray, colors: Optional[np.ndarray]) -> None:
    # Field order of visualization_msgs/msg/Marker (ROS 2 Jazzy).
    w.i32(stamp.sec)
    w.u32(stamp.nanosec)
    w.string(frame_id)
    w.string(ns)
    w.i32(marker_id)
    w.i32(kind)
    w.i32(Marker.ADD)
    w.f64s(*pose)                                         # position, orientation (x, y, z, w)
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
