"""What a device module declares (``Device``), and what its ROS side is built from.

A device's module holds all of it: its layout in a robot model, its world-file settings, its
batched numpy model over a robot group (``read``, which fills its fields of the core's
``GroupReadings``), its topics, how a simulator node publishes its readings each tick
(``DevicePublisher``: every message written as its CDR bytes) and how a controller reads them back
into a ``Tick`` (``reader``). No module here imports ROS: a simulator node hands a publisher
what it needs (``PublishingNode``), and the ROS layer makes publishers from a ``Topic``'s type name.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Optional, Protocol, Sequence, Union

import numpy as np

from composed_sim.devices.common import cdr_clouds
from composed_sim.devices.common.handoff import Batch, hand_readings, take_reading
from composed_sim.devices.common.settings import DeviceSwitch
from composed_sim.devices.common.topic import Topic

# Types of the layers above, named for the reader: a world/robot_models.RobotModel, a
# core/simulation.SensorFrame, a ros/controller.Tick.
RobotModel = SensorFrame = Tick = Any


@dataclass(frozen=True)
class NodeRobots:
    """The robots one simulator node serves, as its device publishers need them."""
    names: Sequence[str]
    models: Sequence[RobotModel]
    devices: Sequence[frozenset[str]]        # per robot: the devices whose topics it has
    tick_ns: int
    rab_payload_bytes: int                   # the world's range_and_bearing.payload_bytes
    global_tf: Optional[Sequence[bool]]      # per robot running tf: on /tf instead of /<r>/tf (None: own)

    def running(self, device: str) -> list[int]:
        """The indices of the robots that have ``device``'s topics."""
        return [i for i, has in enumerate(self.devices) if device in has]


@dataclass
class GroupPlan:
    """A node's robots of one robot group, for publishing from ``frame.groups[group]``."""
    group: int
    model: RobotModel              # the group's model
    rows: np.ndarray               # [k] their simulation rows
    local: np.ndarray              # [k] their indices among the node's robots
    within: np.ndarray             # [k] their rows in the group's arrays
    devices: frozenset[str]        # what the group runs (the same for all its robots)


@dataclass(frozen=True)
class Outgoing:
    """One tick as every device publisher of a node sends it."""
    sec: int                       # the stamp
    nanosec: int
    stamp_ns: int
    stamp_cdr: bytes               # the stamp's 8 CDR bytes (cdr.stamp_bytes)
    failed: list[bool]             # per robot of the node: stopped for good, published no more
    n_failed: int                  # how many (failures are for good: a count tells a change)


class PublishingNode(Protocol):
    """What a device publisher uses of its simulator node (ros/simulator_node.py): publishers
    of a topic's type and QoS, ``/<robot>/<topic>`` or under another name (tf's global /tf)."""
    def create_robot_publisher(self, robot: str, topic: Topic) -> Any: ...
    def create_topic_publisher(self, name: str, topic: Topic) -> Any: ...
    def taps(self, topic: Topic, i: int) -> bool: ...
    def tap_messages(self, topic: Topic, rows: Sequence[int], messages: Sequence, stamp_ns: int) -> None: ...


class DevicePublisher:
    """A node's publishers of one device's sensor topic, one per robot that runs the device, and
    the encoder of each one's messages: every message goes out as its serialized bytes (cdr.py).
    A subclass names its ``topic``, makes a robot's encoder (``template``) and ``publish``es a
    tick for a group's robots."""
    topic: ClassVar[Topic]
    device: ClassVar[str]

    def __init__(self, node: PublishingNode, robots: NodeRobots):
        self.node = node
        n = len(robots.names)
        self.pubs: list = [None] * n
        self.encoders: list = [None] * n
        self._read = [False] * n
        self.checking = True           # ask DDS for readers on every tick (else: its last answers)
        # Per group plan: (n_failed, places, rows) of the last ``to_send`` while not checking:
        # the same until a robot fails or a reader comes (``publish_check``).
        self._sending: dict[int, tuple[int, list[int], list[int]]] = {}
        # Its messages go in process to subscriptions that read the bytes (a controller's
        # readers): hand each message's reading beside them (handoff.py). Set by the host.
        self.hands_readings = False
        for i in self.own_topics(robots):
            self.pubs[i] = node.create_robot_publisher(robots.names[i], self.topic)
            self.encoders[i] = self.template(robots, i)

    def own_topics(self, robots: NodeRobots) -> list[int]:
        """The robots with a topic of their own for the device: all that run it."""
        return robots.running(self.device)

    def template(self, robots: NodeRobots, i: int):
        """The encoder of robot i's messages (``cdr``), which keeps what never changes."""
        raise NotImplementedError

    def publish(self, plan: GroupPlan, frame: SensorFrame, out: Outgoing) -> None:
        raise NotImplementedError

    def finish_tick(self, out: Outgoing) -> None:
        """After every group of a tick (tf's one /tf message of the node)."""

    def wanted(self, i: int, out: Outgoing) -> bool:
        """Publish robot i's message this tick? Never once it failed. Every tick once a subscriber
        has matched (a subscriber that comes later gets every tick from its match on, as with any
        volatile topic); until then DDS is asked, a call instead of a message nobody reads, on
        every tick while ``checking`` (the ROS graph may have changed) and kept otherwise, as
        the in-process links keep theirs (ros/in_process.py, ``GraphWatch``). A recorded topic
        is always published."""
        if out.failed[i]:
            return False
        if not self._read[i] and self.checking:
            self._read[i] = self._has_reader(i)
        return self._read[i]

    def publish_check(self) -> None:
        """Ask DDS now which robots' topics have a reader (before ``checking`` goes off, and after
        the node's recording changed)."""
        for i, pub in enumerate(self.pubs):
            if pub is not None and not self._read[i]:
                self._read[i] = self._has_reader(i)
        self._sending.clear()

    def _has_reader(self, i: int) -> bool:
        """Robot i's topic has a subscriber matched, or is recorded."""
        return self.pubs[i].get_subscription_count() > 0 or self.node.taps(self.topic, i)

    def to_send(self, plan: GroupPlan, out: Outgoing) -> tuple[list[int], list[int]]:
        """The robots of the plan ``wanted`` this tick: (their places k in the plan, their indices
        i in the node). Once every robot of the topic has a reader, only the failed are left out.
        A ``publish`` asks first and takes the frame's readings only when someone is left: they
        are read on first use (core/frames.py), so a topic nobody reads costs no sensing."""
        checking = self.checking
        if not checking:
            sending = self._sending.get(plan.group)
            if sending is not None and sending[0] == out.n_failed:
                return sending[1], sending[2]
        failed, read, wanted = out.failed, self._read, self.wanted
        pairs = [(k, i) for k, i in enumerate(plan.local.tolist())
                 if not failed[i] and (read[i] or checking and wanted(i, out))]
        places, rows = [k for k, _ in pairs], [i for _, i in pairs]
        if not checking:
            self._sending[plan.group] = (out.n_failed, places, rows)
        return places, rows

    def send(self, i: int, msg, out: Outgoing) -> None:
        """Publish robot i's message bytes; the caller asked ``wanted`` first."""
        self.send_all([i], [msg], out)

    def send_all(self, rows: Sequence[int], messages: Sequence, out: Outgoing) -> None:
        """Publish each robot's message bytes (robot ``rows[j]``: ``messages[j]``), the robots
        ``to_send`` chose. One loop over the robots, the fewest Python calls per message: at
        thousands of robots this loop is a good part of the simulator's tick."""
        pubs = self.pubs
        for i, msg in zip(rows, messages):
            pubs[i].publish(msg)
        self.node.tap_messages(self.topic, rows, messages, out.stamp_ns)

    def send_scans(self, places: list[int], rows: list[int], out: Outgoing, ranges: Optional[np.ndarray],
                   intensities: np.ndarray,
                   hand: Optional[Callable[[Optional[np.ndarray], np.ndarray], Batch]] = None) -> None:
        """The LaserScans as bytes (each robot's encoder a ``cdr.ScanEncoder``) of the robots
        ``to_send`` chose, from their rows of ``ranges`` (None: a scan without ranges) and of
        ``intensities`` ([k, m] each, a row per robot of the plan): the rows become float32
        bytes once per tick, and a robot's part is a slice of them. ``hand(ranges, intensities)``:
        the batch of the readers' readings from those float32 rows as float64 (handoff.py)."""
        ranges_f4 = None if ranges is None else np.ascontiguousarray(ranges, dtype="<f4")
        intensities_f4 = np.ascontiguousarray(intensities, dtype="<f4")
        ranges_bytes, rw = (b"", 0) if ranges_f4 is None else (ranges_f4.tobytes(), 4 * ranges_f4.shape[1])
        intensities_bytes, iw = intensities_f4.tobytes(), 4 * intensities_f4.shape[1]
        encoders, stamp = self.encoders, out.stamp_cdr
        messages = [encoders[i].encode_bytes(stamp, ranges_bytes[k * rw:(k + 1) * rw],
                                             intensities_bytes[k * iw:(k + 1) * iw])
                    for k, i in zip(places, rows)]
        if hand is not None and self.hands_readings:
            hand_readings(messages, hand(None if ranges_f4 is None else ranges_f4.astype(float),
                                         intensities_f4.astype(float)), places, out.stamp_ns)
        self.send_all(rows, messages, out)

    def send_clouds(self, places: list[int], rows: list[int], out: Outgoing, points: np.ndarray,
                    offsets: Sequence[int], hand: Optional[Callable[[np.ndarray, Sequence[int]], Batch]] = None) -> None:
        """The PointCloud2s as bytes (each robot's encoder a ``cdr_clouds.CloudEncoder``) of the robots
        ``to_send`` chose: the plan's k-th robot's points are ``points[offsets[k]:offsets[k + 1]]``
        (a structured array laid out as the cloud's fields), turned into bytes once per tick and
        sliced per robot. ``hand(points, offsets)``: the batch of the readers' readings
        (handoff.py)."""
        data, step = points.tobytes(), points.dtype.itemsize
        encoders, stamp = self.encoders, out.stamp_cdr
        messages = [encoders[i].encode_bytes(stamp, data[offsets[k] * step:offsets[k + 1] * step],
                                             offsets[k + 1] - offsets[k])
                    for k, i in zip(places, rows)]
        if hand is not None and self.hands_readings:
            hand_readings(messages, hand(points, offsets), places, out.stamp_ns)
        self.send_all(rows, messages, out)

    def encode_and_send(self, places: list[int], rows: list[int], out: Outgoing, *columns: Sequence) -> None:
        """Each robot ``to_send`` chose, the plan's k-th: its encoder's bytes (``cdr.FixedEncoder``)
        of the stamp and ``column[k]`` …, published. A column holds one value per robot of the plan."""
        encoders, stamp = self.encoders, out.stamp_cdr
        self.send_all(rows, [encoders[i].encode(stamp, *[column[k] for column in columns])
                             for k, i in zip(places, rows)], out)


# How a controller reads a device's sensor topic: made once per controller (from its robot's
# model), then called with each tick's message as serialized bytes and the Tick to fill.
Reader = Callable[[bytes, Tick], None]


def reads_into(fields: Union[str, tuple[str, ...]], decode: Callable) -> Callable[[RobotModel], Reader]:
    """The reader of a message that ``decode`` turns into the Tick's ``fields`` (one, or a tuple
    that ``decode`` returns in that order), whatever the robot's model."""
    def reader(model: RobotModel) -> Reader:
        if isinstance(fields, str):
            def read_one(data, tick) -> None:
                value = take_reading(data)
                setattr(tick, fields, decode(data) if value is None else value)
            return read_one

        def read(data, tick) -> None:
            values = take_reading(data)
            for field, value in zip(fields, decode(data) if values is None else values):
                setattr(tick, field, value)
        return read
    return reader


def reads_cloud_into(field: str, decode: Callable) -> Callable[[RobotModel], Reader]:
    """The reader of a PointCloud2 that ``decode(data, decoder)`` turns into the Tick's ``field``,
    with a ``cdr_clouds.CloudDecoder`` per controller: its stream's layout is parsed once."""
    def reader(model: RobotModel) -> Reader:
        decoder = cdr_clouds.CloudDecoder()

        def read(data, tick) -> None:
            value = take_reading(data)
            setattr(tick, field, decode(data, decoder) if value is None else value)
        return read
    return reader


@dataclass(frozen=True)
class Device:
    """One device, as its module declares it (``DEVICE``)."""
    name: str                                          # as world files and robot models spell it
    topics: tuple[Topic, ...]                          # every contract topic it gives a robot
    publisher: type[DevicePublisher]                   # the simulator's side of its topics
    # The controller's side of its sensor topic, taken as serialized bytes and decoded straight
    # into arrays (cdr.py): the same messages without Python message objects.
    reader: Optional[Callable[[RobotModel], Reader]]
    tick_fields: tuple[str, ...] = ()                  # the Tick fields its reader fills
    settings: type[DeviceSwitch] = DeviceSwitch        # its settings in a world file's ``devices``
    # Its layout class, a field of the robot models that carry it. None: a device that needs no
    # layout, which the core computes for every robot and whose topics a world file switches on.
    layout: Optional[type] = None
    # A device with a layout read per robot group: read(sensing, group, readings) fills its fields
    # of the group's GroupReadings, over all the group's robots at once.
    read: Optional[Callable[[Any, Any, Any], None]] = None
    readings: tuple[str, ...] = ()                     # those fields: [g, …] arrays, a row per robot
    csr_readings: tuple[str, ...] = ()                 # … and CSR readings (``offsets`` [g+1], entries)
    on_robot: bool = True                              # False: not the robot's (tf: frames of others' readings)

    @property
    def sensor_topic(self) -> Optional[Topic]:
        return self.topics[0] if self.topics[0].direction == "sensor" else None


def csr_take(offsets: np.ndarray, rows: np.ndarray):
    """The entries of CSR rows ``rows`` [k] (ascending) of entry arrays with row offsets
    ``offsets``: (what to take from the entry arrays, [k+1] offsets into what is taken).

    A simulator node serves a block or a domain of the swarm: converting every robot's entries
    (blobs, range-and-bearing messages) in every node would cost (number of nodes) × the work."""
    starts, ends = offsets[rows], offsets[rows + 1]
    counts = ends - starts
    local = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(counts, out=local[1:])
    if len(rows) and rows[-1] - rows[0] + 1 == len(rows):     # contiguous rows: a slice
        return slice(int(starts[0]), int(ends[-1])), local
    return np.arange(local[-1]) + np.repeat(starts - local[:-1], counts), local
