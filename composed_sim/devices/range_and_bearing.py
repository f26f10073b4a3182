"""Range-and-bearing communication: every equipped robot broadcasts a payload each tick.

ARGoS (docs/architecture.md, "Range and bearing"; ``range_and_bearing_medium.cpp`` and
``range_and_bearing_default_sensor.cpp``): receiver A gets sender B's payload when their
emitters are closer than B's range and, with occlusion checking on, the segment between them
crosses no third body. A reading holds the range, the horizontal bearing in A's frame in
[-π, π], the vertical bearing (elevation above A's horizontal plane, as ARGoS's
``CCI_RangeAndBearingSensor::SPacket`` defines it) and B's payload bytes. One message per sender
per tick, no queue. Receiver noise: a random vector of length N(0, σ), inclination uniform in
[0, π] and azimuth uniform in [0, 2π) (as ARGoS draws it), added to the sender's relative position; packet drop: each message is lost with the
receiver's probability. Units are SI (ARGoS's cm ranges are metres here).

The medium works on the emitters' positions after physics and on the payloads set before the
tick, so a payload set at tick k is received at tick k + 1 (the caller's job: see
``Simulation.step``). "global" mode skips range and occlusion: everyone hears everyone.

``/<r>/rab_rx``, sensor_msgs/PointCloud2 in base_link: the messages heard this tick, one point per
sender: x/y/z of its emitter (m), range (m), bearing (horizontal, rad), elevation (vertical bearing,
rad), float32; payload = its bytes (uint8, count = payload_bytes). A controller's Tick: ``rab``.
``/<r>/rab_tx``, std_msgs/UInt8MultiArray from the controller: exactly payload_bytes bytes,
broadcast from the next tick on (heard one tick later), kept until changed. The simulator node
drains it with the LEDs at the act phase (ros/decoding.py).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Literal, Optional, Sequence

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common import cdr_clouds
from composed_sim.devices.common.device import Device, DevicePublisher, csr_take, reads_cloud_into
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.common.noise import entry_noise
from composed_sim.devices.common.poses import wrap_angle
from composed_sim.devices.common.sensors import _pair_order, blocked_by_robots, kd_tree, near_pairs
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat, PositiveFloat, Probability
from composed_sim.devices.common.topic import Topic, base_link

NAME = "range_and_bearing"


@dataclass(frozen=True)
class RangeAndBearingDevice:
    """Range-and-bearing emitter/receiver pair on the robot's vertical axis."""
    elevation_m: float      # above the robot's origin (floor level)
    range_m: float          # default emission range; a world file may change it per group


class RangeAndBearingConfig(DeviceSwitch):
    range_m: Optional[PositiveFloat] = None          # None: the robot model's
    packet_drop_probability: Probability = 0.0
    noise_std_m: NonNegativeFloat = 0.0


Mode = Literal["local", "global"]


@dataclass
class RangeAndBearingReadings:
    """Every robot's received messages, CSR by receiver: robot i's are rows offsets[i]:offsets[i+1],
    ordered by sender. Robots without the device have none."""
    offsets: np.ndarray              # [n+1] int64
    senders: np.ndarray              # [m] intp, index of the sending robot
    ranges: np.ndarray               # [m] m, emitter to emitter
    horizontal_bearings: np.ndarray  # [m] rad in the receiver's frame, (-pi, pi]
    vertical_bearings: np.ndarray    # [m] rad, elevation above the receiver's horizontal plane
    payloads: np.ndarray             # [m, B] uint8

    def of(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(senders, ranges, horizontal bearings, vertical bearings, payloads) of robot i."""
        s = slice(self.offsets[i], self.offsets[i + 1])
        return (self.senders[s], self.ranges[s], self.horizontal_bearings[s],
                self.vertical_bearings[s], self.payloads[s])

    @classmethod
    def empty(cls, n: int, payload_bytes: int) -> "RangeAndBearingReadings":
        return cls(offsets=np.zeros(n + 1, dtype=np.int64), senders=np.zeros(0, dtype=np.intp),
                   ranges=np.zeros(0), horizontal_bearings=np.zeros(0), vertical_bearings=np.zeros(0),
                   payloads=np.zeros((0, payload_bytes), dtype=np.uint8))


def range_and_bearing(positions: np.ndarray, headings: np.ndarray, radii: np.ndarray,
                      heights: np.ndarray, equipped: np.ndarray, elevations: np.ndarray,
                      ranges: np.ndarray, payloads: np.ndarray, scene: StaticScene, *,
                      mode: Mode = "local", check_occlusions: bool = True,
                      drop_probability: Optional[np.ndarray] = None,
                      noise_std_m: Optional[np.ndarray] = None,
                      rng=None, tree: Optional[cKDTree] = None,
                      receivers: Optional[slice] = None) -> RangeAndBearingReadings:
    """Route one tick's messages.

    positions [n, 2], headings [n], radii [n], heights [n] of all robots (all of them are
    bodies that can occlude); equipped [n] bool: the robot has a running RAB device;
    elevations [n] m: emitter height above the floor; ranges [n] m: each sender's range;
    payloads [n, B] uint8: what each robot sends; drop_probability [n] and noise_std_m [n]:
    each receiver's packet-drop probability and position-noise σ (None: none); ``rng``: a
    Generator or a RowNoise (noise.py: each message's draws keyed by its receiver and sender);
    ``receivers``: route only the messages to these robots (a worker's block; CSR over them).
    """
    positions = np.asarray(positions, dtype=np.float64)
    n = len(positions)
    payloads = np.asarray(payloads, dtype=np.uint8)
    _check_inputs(n, payloads, headings, radii, heights, equipped, elevations, ranges, mode)
    noisy = noise_std_m is not None and np.any(noise_std_m > 0.0)
    dropping = drop_probability is not None and np.any(drop_probability > 0.0)
    if (noisy or dropping) and rng is None:
        raise ValueError("packet drop or noise needs a random generator (rng=)")
    equipped = np.asarray(equipped, dtype=bool)
    members = np.flatnonzero(equipped)
    rows = slice(0, n) if receivers is None else receivers
    if len(members) < 2:
        return RangeAndBearingReadings.empty(rows.stop - rows.start, payloads.shape[1])
    emitters = np.column_stack([positions, np.asarray(elevations, dtype=np.float64)])   # [n, 3]
    if mode == "global":
        rx, tx = _heard_globally(members)
    else:
        rx, tx = _heard_locally(positions, emitters, radii, heights, equipped, members, ranges, scene,
                                check_occlusions, kd_tree(positions) if tree is None else tree, receivers, rows)
    if receivers is not None:        # sorted by receiver: the block's messages are contiguous
        first, last = np.searchsorted(rx, [rows.start, rows.stop])
        rx, tx = rx[first:last], tx[first:last]
    draws = entry_noise(rng, rx, tx) if (dropping or noisy) else None     # per receiver and sender
    if dropping:
        kept = draws.random(0) >= drop_probability[rx]
        rx, tx = rx[kept], tx[kept]
        draws = entry_noise(rng, rx, tx) if noisy else None
    v = emitters[tx] - emitters[rx]                                   # [m, 3] world frame
    if noisy:
        v = v + _receiver_noise(draws, noise_std_m[rx])
    return _readings(rx, tx, v, headings, payloads, rows)


def _receiver_noise(draws, sigma_m: np.ndarray) -> np.ndarray:
    """[m, 3] world-frame noise vectors, one per message, from its draws and its receiver's σ [m]:
    as ARGoS, a CVector3 from spherical coordinates (Gaussian length, uniform inclination, uniform
    azimuth)."""
    length = draws.normal(0.0, 1.0, 1) * sigma_m
    inclination = draws.uniform(0.0, math.pi, 2)
    azimuth = draws.uniform(0.0, 2.0 * math.pi, 3)
    return (length * np.stack([np.sin(inclination) * np.cos(azimuth),
                               np.sin(inclination) * np.sin(azimuth),
                               np.cos(inclination)])).T


def _readings(rx: np.ndarray, tx: np.ndarray, v: np.ndarray, headings, payloads: np.ndarray,
              rows: slice) -> RangeAndBearingReadings:
    """The messages heard, receivers rx [m] (sorted) from senders tx [m], each sender's emitter at
    v [m, 3] (world frame) from its receiver's, as the readings of the receivers ``rows``."""
    planar = np.hypot(v[:, 0], v[:, 1])
    offsets = np.zeros(rows.stop - rows.start + 1, dtype=np.int64)
    np.cumsum(np.bincount(rx - rows.start, minlength=rows.stop - rows.start), out=offsets[1:])
    return RangeAndBearingReadings(
        offsets=offsets, senders=tx.astype(np.intp),
        ranges=np.sqrt(planar * planar + v[:, 2] * v[:, 2]),
        horizontal_bearings=wrap_angle(np.arctan2(v[:, 1], v[:, 0]) - headings[rx]),
        vertical_bearings=np.arctan2(v[:, 2], planar),
        payloads=payloads[tx])


def _check_inputs(n: int, payloads: np.ndarray, headings, radii, heights, equipped, elevations, ranges,
                  mode: str) -> None:
    if payloads.ndim != 2 or len(payloads) != n:
        raise ValueError(f"payloads must have shape ({n}, B), got {payloads.shape}")
    for name, a in (("headings", headings), ("radii", radii), ("heights", heights),
                    ("equipped", equipped), ("elevations", elevations), ("ranges", ranges)):
        if np.shape(a) != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {np.shape(a)}")
    if mode not in ("local", "global"):
        raise ValueError(f"mode must be 'local' or 'global', got {mode!r}")


def _heard_globally(members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(receivers [m], senders [m]): every ordered pair of distinct ``members``, by receiver then
    sender ("global" mode: no range, no occlusion)."""
    rx, tx = np.meshgrid(members, members, indexing="ij")     # receiver-major, sender order
    keep = rx != tx
    return rx[keep], tx[keep]


def _heard_locally(positions: np.ndarray, emitters: np.ndarray, radii, heights, equipped: np.ndarray,
                   members: np.ndarray, ranges: np.ndarray, scene: StaticScene, check_occlusions: bool,
                   tree: cKDTree, receivers: Optional[slice], rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """(receivers [m], senders [m]) of the messages heard, by receiver then sender: each pair of
    equipped robots within range (3D, emitters at their heights), not occluded."""
    # Planar pairs within the longest range; the 3D test below is exact (emitters differ in height).
    reach = float(np.max(ranges[members]))
    if receivers is None:
        pairs = tree.query_pairs(reach, output_type="ndarray").astype(np.intp)
        a, b = pairs[:, 0], pairs[:, 1]
    else:    # only the pairs with a receiver in the block, found from the block (a worker's)
        a, b = near_pairs(tree, positions, reach, np.arange(rows.start, rows.stop))
        once = (a < b) | (b < rows.start) | (b >= rows.stop)       # a pair inside the block once
        a, b = np.minimum(a[once], b[once]), np.maximum(a[once], b[once])   # lower index first, as above
    both = np.flatnonzero(equipped[a] & equipped[b])
    a, b = a[both], b[both]
    v = emitters[b] - emitters[a]
    d2 = np.einsum("ij,ij->i", v, v)
    a_hears_b, b_hears_a = d2 < ranges[b] ** 2, d2 < ranges[a] ** 2
    either = np.flatnonzero(a_hears_b | b_hears_a)
    a, b, a_hears_b, b_hears_a = a[either], b[either], a_hears_b[either], b_hears_a[either]
    if check_occlusions and len(a):
        # The segment between two emitters is the same both ways: test each pair once.
        p0, p1 = emitters[a], emitters[b]
        clear = ~(scene.blocks(p0, p1) | blocked_by_robots(p0, p1, a, b, positions, np.asarray(radii, float),
                                                            np.asarray(heights, float), tree))
        a_hears_b &= clear
        b_hears_a &= clear
    rx = np.concatenate([a[a_hears_b], b[b_hears_a]])
    tx = np.concatenate([b[a_hears_b], a[b_hears_a]])
    order = _pair_order(rx, tx, len(positions))
    return rx[order], tx[order]


# --- its topics -----------------------------------------------------------------------------------

RX = Topic("rab_rx", "sensor_msgs/msg/PointCloud2", "sensor",
           "range-and-bearing messages heard this tick, one point per sender: x/y/z of its "
           "emitter in base_link (m), range (m), bearing (horizontal, rad), elevation (vertical "
           "bearing, rad), float32; payload = its bytes (uint8, count = payload_bytes)")
TX = Topic("rab_tx", "std_msgs/msg/UInt8MultiArray", "actuator",
           "range-and-bearing payload: data = exactly payload_bytes bytes, broadcast from the next "
           "tick on (heard one tick later), kept until changed")


def point_dtype(payload_bytes: int) -> np.dtype:
    """One range-and-bearing point: emitter position, the ARGoS reading, the payload bytes."""
    return np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("range", "<f4"), ("bearing", "<f4"),
                     ("elevation", "<f4"), ("payload", "u1", (payload_bytes,))])


def encoder(robot: str, payload_bytes: int) -> cdr_clouds.CloudEncoder:
    return cdr_clouds.CloudEncoder(cdr_clouds.cloud_bytes(base_link(robot), point_dtype(payload_bytes)))


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


@dataclass(frozen=True)
class RabMessages:
    """The range-and-bearing messages one robot heard in a tick (one per sender, no sender id)."""
    ranges: np.ndarray      # [m] m, emitter to emitter
    bearings: np.ndarray    # [m] rad, horizontal, relative to the heading, CCW
    elevations: np.ndarray  # [m] rad, vertical bearing
    payloads: np.ndarray    # [m, B] uint8

    def __len__(self) -> int:
        return len(self.ranges)


def decode(data: bytes, decoder: Optional[cdr_clouds.CloudDecoder] = None) -> RabMessages:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr_clouds.CloudDecoder()).decode(data)
    payload_bytes = point_step - _HEAD_BYTES
    if payload_bytes < 0 or fields != _cloud_fields(payload_bytes):
        raise ValueError(f"not a rab_rx cloud: fields {[name for name, _, _ in fields]} (need x, y, z, range, "
                         f"bearing, elevation float32 and payload uint8)")
    return _messages(np.frombuffer(points, dtype=point_dtype(payload_bytes), count=width))


def _messages(points: np.ndarray) -> RabMessages:
    return RabMessages(points["range"].astype(float), points["bearing"].astype(float),
                       points["elevation"].astype(float), points["payload"].copy())


def _handed(points: np.ndarray, offsets: Sequence[int]) -> Callable[[int], RabMessages]:
    """The k-th cloud's ``decode``, for every cloud of ``points`` at once (devices/common/handoff.py)."""
    whole = _messages(points)

    def of(k: int) -> RabMessages:
        start, end = offsets[k], offsets[k + 1]
        return RabMessages(whole.ranges[start:end], whole.bearings[start:end], whole.elevations[start:end],
                           whole.payloads[start:end])
    return of


_HEAD_BYTES = point_dtype(0).itemsize      # a point's bytes before its payload


@functools.lru_cache(maxsize=None)
def _cloud_fields(payload_bytes: int) -> tuple:
    """A rab_rx cloud's (name, offset, datatype) per field, as ``cdr_clouds.CloudDecoder`` gives them."""
    return tuple((name, offset, datatype)
                 for name, offset, datatype, _ in cdr_clouds.point_fields(point_dtype(payload_bytes)))


class Publisher(DevicePublisher):
    topic, device = RX, NAME

    def template(self, robots, i):
        return encoder(robots.names[i], robots.rab_payload_bytes)

    def publish(self, plan, frame, out):
        rab = frame.range_and_bearing
        take, offsets = csr_take(rab.offsets, plan.rows)
        points = points_of(rab.ranges[take], rab.horizontal_bearings[take], rab.vertical_bearings[take],
                           rab.payloads[take])
        self.send_clouds(*self.to_send(plan, out), out, points, offsets.tolist(), hand=_handed)


DEVICE = Device(NAME, (RX, TX), Publisher, reads_cloud_into("rab", decode), tick_fields=("rab",),
                settings=RangeAndBearingConfig, layout=RangeAndBearingDevice)
