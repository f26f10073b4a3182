"""Camera: the omnidirectional coloured-blob camera (readings: core/devices/camera.py).

``/<r>/blobs``, sensor_msgs/PointCloud2 in base_link: one point per blob, x/y of the seen LED (m;
z = 0, the camera is planar), rgb = 0x00RRGGBB (uint32). Published and taken as bytes; a
controller gets ``Blobs`` (bearing, distance, colour per blob).
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, csr_take, reads_cloud_into
from composed_sim.ros.topic import Topic, fill_points, point_cloud, point_fields
from composed_sim.world.robot_models import CAMERA

TOPIC = Topic("blobs", PointCloud2, "sensor",
              "coloured-blob omnidirectional camera: one point per blob, x/y of the LED in "
              "base_link (m; z = 0, the camera is planar), rgb = 0x00RRGGBB (uint32)")

# One point per blob. float32 coordinates are ample for a camera with cm-level range.
BLOB_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
BLOB_FIELDS = point_fields(BLOB_DTYPE)


def message(robot: str) -> PointCloud2:
    return point_cloud(robot, BLOB_DTYPE)


def encoder(robot: str) -> cdr.CloudEncoder:
    return cdr.CloudEncoder(message(robot))


def points_of(angles: np.ndarray, distances: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """Blobs given as (bearing [m], planar distance [m], RGB [m,3]) → BLOB_DTYPE points (z = 0)."""
    points = np.empty(len(angles), dtype=BLOB_DTYPE)
    points["x"] = distances * np.cos(angles)
    points["y"] = distances * np.sin(angles)
    points["z"] = 0.0
    c = colors.astype(np.uint32)
    points["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    return points


fill = fill_points          # (msg, stamp, BLOB_DTYPE points, one per blob)


class Publisher(DevicePublisher):
    topic, device = TOPIC, CAMERA

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        blobs = frame.groups[plan.group].blobs
        take, local = csr_take(blobs.offsets, plan.within)
        self.send_clouds(plan, out, points_of(blobs.angles[take], blobs.distances[take], blobs.colors[take]),
                         local.tolist())


# --- the controller's side -----------------------------------------------------------------------

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


def decode(msg: PointCloud2) -> Blobs:
    fields = tuple((f.name, f.offset, f.datatype) for f in msg.fields)
    return _blobs(np.frombuffer(msg.data, dtype=_cloud_dtype(fields, msg.point_step), count=msg.width))


def decode_cdr(data: bytes, decoder: Optional[cdr.CloudDecoder] = None) -> Blobs:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr.CloudDecoder()).decode(data)
    return _blobs(np.frombuffer(points, dtype=_cloud_dtype(fields, point_step), count=width))


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


DEVICE = Device(CAMERA, (TOPIC,), Publisher, reads_cloud_into("blobs", decode_cdr))
