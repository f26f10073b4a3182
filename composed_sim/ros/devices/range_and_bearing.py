"""Range and bearing: the situated communication device (readings: core/range_and_bearing).

``/<r>/rab_rx``, sensor_msgs/PointCloud2 in base_link: the messages heard this tick, one point per
sender: x/y/z of its emitter (m), range (m), bearing (horizontal, rad), elevation (vertical bearing,
rad), float32; payload = its bytes (uint8, count = payload_bytes). Published and taken as bytes.
``/<r>/rab_tx``, std_msgs/UInt8MultiArray from the controller: exactly payload_bytes bytes,
broadcast from the next tick on (heard one tick later), kept until changed. The simulator node
drains it with the LEDs at the act phase.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Optional

import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray

from composed_sim.ros import cdr
from composed_sim.ros.devices.device import Device, DevicePublisher, csr_take, reads_cloud_into
from composed_sim.ros.topic import Topic, fill_points, point_cloud, point_fields
from composed_sim.world.robot_models import RANGE_AND_BEARING

RX = Topic("rab_rx", PointCloud2, "sensor",
           "range-and-bearing messages heard this tick, one point per sender: x/y/z of its "
           "emitter in base_link (m), range (m), bearing (horizontal, rad), elevation (vertical "
           "bearing, rad), float32; payload = its bytes (uint8, count = payload_bytes)")
TX = Topic("rab_tx", UInt8MultiArray, "actuator",
           "range-and-bearing payload: data = exactly payload_bytes bytes, broadcast from the next "
           "tick on (heard one tick later), kept until changed")


def point_dtype(payload_bytes: int) -> np.dtype:
    """One range-and-bearing point: emitter position, the ARGoS reading, the payload bytes."""
    return np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("range", "<f4"), ("bearing", "<f4"),
                     ("elevation", "<f4"), ("payload", "u1", (payload_bytes,))])


def message(robot: str, payload_bytes: int) -> PointCloud2:
    return point_cloud(robot, point_dtype(payload_bytes))


def encoder(robot: str, payload_bytes: int) -> cdr.CloudEncoder:
    return cdr.CloudEncoder(message(robot, payload_bytes))


def points_of(ranges: np.ndarray, bearings: np.ndarray, elevations: np.ndarray,
              payloads: np.ndarray) -> np.ndarray:
    """m messages: ranges, horizontal bearings, vertical bearings [m], payloads [m, B] → [m] points."""
    payloads = np.asarray(payloads, dtype=np.uint8)
    points = np.empty(len(ranges), dtype=point_dtype(payloads.shape[1]))
    planar = ranges * np.cos(elevations)
    points["x"] = planar * np.cos(bearings)
    points["y"] = planar * np.sin(bearings)
    points["z"] = ranges * np.sin(elevations)
    points["range"] = ranges
    points["bearing"] = bearings
    points["elevation"] = elevations
    points["payload"] = payloads
    return points


fill = fill_points          # (msg, stamp, one robot's ``points_of``)


@dataclass(frozen=True)
class RabMessages:
    """The range-and-bearing messages one robot heard in a tick (one per sender, no sender id)."""
    ranges: np.ndarray      # [m] m, emitter to emitter
    bearings: np.ndarray    # [m] rad, horizontal, relative to the heading, CCW
    elevations: np.ndarray  # [m] rad, vertical bearing
    payloads: np.ndarray    # [m, B] uint8

    def __len__(self) -> int:
        return len(self.ranges)


def decode(msg: PointCloud2) -> RabMessages:
    fields = {f.name: f for f in msg.fields}
    payload = fields.get("payload")
    if payload is None:
        raise ValueError("rab_rx message has no 'payload' field")
    points = np.frombuffer(msg.data, dtype=point_dtype(payload.count), count=msg.width)
    return RabMessages(points["range"].astype(float), points["bearing"].astype(float),
                       points["elevation"].astype(float), points["payload"].copy())


def decode_cdr(data: bytes, decoder: Optional[cdr.CloudDecoder] = None) -> RabMessages:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr.CloudDecoder()).decode(data)
    payload_bytes = point_step - _HEAD_BYTES
    if payload_bytes < 0 or fields != _cloud_fields(payload_bytes):
        raise ValueError(f"not a rab_rx cloud: fields {[name for name, _, _ in fields]} (need x, y, z, range, "
                         f"bearing, elevation float32 and payload uint8)")
    points = np.frombuffer(points, dtype=point_dtype(payload_bytes), count=width)
    return RabMessages(points["range"].astype(float), points["bearing"].astype(float),
                       points["elevation"].astype(float), points["payload"].copy())


_HEAD_BYTES = point_dtype(0).itemsize      # a point's bytes before its payload


@functools.lru_cache(maxsize=None)
def _cloud_fields(payload_bytes: int) -> tuple:
    """A rab_rx cloud's (name, offset, datatype) per field, as ``cdr.CloudDecoder`` gives them."""
    return tuple((f.name, f.offset, f.datatype) for f in point_fields(point_dtype(payload_bytes)))


def payload_message(data) -> UInt8MultiArray:
    """A payload (bytes or [B] uint8) as the rab_tx message."""
    payload = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray)) \
        else np.asarray(data, dtype=np.uint8).reshape(-1)
    msg = UInt8MultiArray()
    msg.layout.dim = [MultiArrayDimension(label="byte", size=payload.size, stride=payload.size)]
    msg.data = payload.tobytes()
    return msg


def decode_payload(msg: UInt8MultiArray, payload_bytes: int) -> np.ndarray:
    """→ [B] uint8; ValueError when the message does not carry exactly payload_bytes bytes."""
    data = np.frombuffer(msg.data, dtype=np.uint8)
    if data.size != payload_bytes:
        raise ValueError(f"rab_tx message has {data.size} bytes, expected {payload_bytes} "
                         f"(range_and_bearing.payload_bytes of the world file)")
    return data


class Publisher(DevicePublisher):
    topic, device = RX, RANGE_AND_BEARING

    def template(self, robots, i):
        return encoder(robots.names[i], robots.rab_payload_bytes)

    def publish(self, plan, frame, out):
        rab = frame.range_and_bearing
        take, offsets = csr_take(rab.offsets, plan.rows)
        points = points_of(rab.ranges[take], rab.horizontal_bearings[take], rab.vertical_bearings[take],
                           rab.payloads[take])
        self.send_clouds(plan, out, points, offsets.tolist())


DEVICE = Device(RANGE_AND_BEARING, (RX, TX), Publisher, reads_cloud_into("rab", decode_cdr))
