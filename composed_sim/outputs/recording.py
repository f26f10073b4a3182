"""Record a run as a rosbag2 directory (MCAP storage, sim-time stamps) and read it back.

A recording is what ``ros2 bag info``, ``ros2 bag play`` and Foxglove open: ``DIR/metadata.yaml``
plus ``DIR/DIR.mcap``. Every message is logged at its sim time (tick ``k`` at ``k * tick_ns``
nanoseconds), so a bag starts at time 0, not at the wall-clock time of the run.

Topics
  /clock         rosgraph_msgs/msg/Clock          once per tick (``write_clock``)
  /swarm/state   sensor_msgs/msg/PointCloud2      once per tick, every robot in one message
                                                  (``write_swarm_state``; layout below)
  /swarm/markers visualization_msgs/msg/MarkerArray  once per tick in a run's bag: the scene
                                                  Foxglove draws (live/markers.py, live/observers.py)
  any other      whatever rclpy message is given   only topics matching the recorder's globs
                                                  (``wants``, ``write_message``)

The swarm state is one PointCloud2 per tick, one point per robot in the order of
``robot_names`` (frame ``world``): a standard type that Foxglove and RViz draw as coloured
points without any plugin, that carries poses and colours of all robots in one message (one
PoseArray would need a second message for the colours), and whose payload is one numpy
buffer, so writing it costs the same for 10 or 1280 robots apart from the copy. Fields,
``STATE_DTYPE`` (40 bytes per robot, little-endian):

  x, y, z  float64  position in m (z = 0: the simulation is planar)
  yaw      float64  heading in rad, CCW from the x axis
  rgb      uint32   0x00RRGGBB, the robot's display LED colour (``display_colors``); 0 = no LED lit
  id       uint32   the robot's index in ``robot_names``

float64 keeps the recorded poses bit-identical to the run's trajectories, so a replay
recomputes the same figures; the extra 16 bytes per robot are negligible (51 kB per tick
at 1280 robots before zstd chunk compression).

The recorder also stores, as rosbag2 ``custom_data`` (in metadata.yaml and in the MCAP's
metadata record), what a replay needs without the results directory:
``composed_sim.robot_names`` (JSON list), ``composed_sim.tick_s``, ``composed_sim.ticks``
(the ticks simulated, as summary.json counts them), ``composed_sim.world`` (the resolved world as
YAML, when given) and ``composed_sim.executor`` (what ``replay --check`` re-simulates with).

A recording survives a kill. Every ``FLUSH_EVERY_TICKS`` ticks, or ``FLUSH_EVERY_S`` of wall time,
whichever comes first, the chunk in progress is ended and the file synced to disk (``flush``):
the MCAP file then ends on a complete record, so a process killed with SIGKILL, or a machine
losing power, leaves every tick up to the last flush readable by an MCAP stream reader. What
``close`` writes at the end (the MCAP summary and index, metadata.yaml) is what such a bag lacks;
``composed-sim bag repair`` writes it (outputs/bag_repair.py) from the chunks and from ``UNFINISHED``, the
custom_data kept beside the MCAP file from the start and deleted by ``close``: its presence, with
no metadata.yaml, marks a recording that was never closed. A write that fails (a full disk) cuts
the MCAP file back to its last flush and raises an OSError naming the file.

rosbags (pure Python) writes and reads the bag; message definitions and type hashes come from
its ROS 2 Jazzy typestore, so the MCAP schemas are the real ``ros2msg`` definitions. A type the
typestore lacks is loaded from the ``share/<package>/msg/<Type>.msg`` file of the installed
interface package (the venv or $AMENT_PREFIX_PATH).
"""
from __future__ import annotations

import errno
import functools
import json
import math
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Optional

import numpy as np

from composed_sim.devices.common.poses import checked_poses
from composed_sim.world.robot_models import display_colors
from composed_sim.ros.global_topics import CLOCK_TOPIC, SWARM_STATE_TOPIC
from composed_sim.ros.global_topics import WORLD_FRAME as FRAME_ID
from composed_sim.ros.taps import TopicGlobs

if TYPE_CHECKING:
    from composed_sim.world.schema import World

SWARM_STATE_TYPE = "sensor_msgs/msg/PointCloud2"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"

# One point per robot; 40 bytes keeps every float64 8-byte aligned from point to point.
STATE_DTYPE = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("yaw", "<f8"),
                        ("rgb", "<u4"), ("id", "<u4")])

CUSTOM_PREFIX = "composed_sim."     # of our custom_data keys
_NS_PER_S = 1_000_000_000
_BAG_VERSION = 9            # the rosbag2 metadata version of ROS 2 Jazzy

# How much a killed run may lose from its recording: each flush ends a chunk (so compression
# works on smaller chunks) and syncs the file (docs/faults.md gives the cost).
FLUSH_EVERY_TICKS = 50
FLUSH_EVERY_S = 5.0
UNFINISHED = "unfinished.yaml"      # the custom_data of a recording not yet closed


class RecordingError(Exception):
    """A recording that cannot be written or read; the message names the bag and the problem."""


# --- colours -----------------------------------------------------------------------------

def pack_rgb(colors: np.ndarray) -> np.ndarray:
    """[n, 3] uint8 → [n] uint32 0x00RRGGBB."""
    c = colors.astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


def unpack_rgb(rgb: np.ndarray) -> np.ndarray:
    """[...] uint32 0x00RRGGBB → [..., 3] uint8."""
    rgb = np.asarray(rgb, dtype=np.uint32)
    return np.stack([(rgb >> 16) & 0xFF, (rgb >> 8) & 0xFF, rgb & 0xFF], axis=-1).astype(np.uint8)


# --- message types -----------------------------------------------------------------------

def ros_type_name(msg: Any) -> str:
    """'geometry_msgs/msg/TwistStamped' for an rclpy message (or its class)."""
    cls = msg if isinstance(msg, type) else type(msg)
    parts = cls.__module__.split(".")
    if len(parts) < 2 or parts[1] not in ("msg", "srv", "action"):
        raise ValueError(f"not an rclpy message: {cls.__module__}.{cls.__qualname__}")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def _new_typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


@functools.lru_cache(maxsize=None)
def message_definition(msgtype: str) -> tuple[str, str]:
    """(the ``ros2msg`` definition with its dependencies, the RIHS01 type hash) of a ROS 2
    message type: what a bag's schema holds, and what a Foxglove server advertises."""
    typestore = _definitions_typestore()
    if msgtype not in typestore.fielddefs:
        _ensure_type(typestore, msgtype)
    msgdef, _ = typestore.generate_msgdef(msgtype, ros_version=2)   # ~5 ms: once per type
    return msgdef, typestore.hash_rihs01(msgtype)


@functools.lru_cache(maxsize=1)
def _definitions_typestore():
    return _new_typestore()


def _interface_dirs() -> list[Path]:
    """Where installed interface packages keep their .msg files (share/<pkg>/msg)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes]


def _ensure_type(typestore, name: str) -> None:
    """Register ``name`` (and the types it uses) from its .msg file if the typestore lacks it."""
    from rosbags.typesys import get_types_from_msg

    pending, found = [name], {}
    while pending:
        typ = pending.pop()
        if typ in typestore.fielddefs or typ in found:
            continue
        pkg, kind, short = typ.split("/")
        path = next((d / pkg / kind / f"{short}.msg" for d in _interface_dirs()
                     if (d / pkg / kind / f"{short}.msg").is_file()), None)
        if path is None:
            raise RecordingError(f"message type {typ}: not in the rosbags typestore and no "
                                 f"{pkg}/{kind}/{short}.msg under {', '.join(map(str, _interface_dirs()))}")
        parsed = get_types_from_msg(path.read_text(encoding="utf-8"), typ)
        found.update(parsed)
        pending += [t for t in _referenced_types(parsed) if t not in typestore.fielddefs]
    typestore.register(found)


def _referenced_types(typesdict: dict) -> set[str]:
    """Every 'pkg/msg/Type' named inside parsed field definitions."""
    out: set[str] = set()
    stack: list = list(typesdict.values())
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            if re.fullmatch(r"[A-Za-z]\w*/(msg|srv|action)/\w+", item):
                out.add(item)
        elif isinstance(item, (tuple, list)):
            stack.extend(item)
    return out


def _qos_profiles():
    """The contract's QoS (reliable, keep last 10, volatile), for `ros2 bag play`."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    never = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=10, reliability=QosReliability.RELIABLE,
                durability=QosDurability.VOLATILE, deadline=never, lifespan=never,
                liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
                avoid_ros_namespace_conventions=False)]


# --- writing -----------------------------------------------------------------------------

class BagRecorder:
    """A rosbag2/MCAP recording of one run; a context manager that always leaves a readable bag.

    ``path`` is the bag directory to create (it must not exist). ``topics_globs`` selects the
    per-robot topics that ``write_message`` records (``fnmatch`` patterns on the full topic
    name, ``*`` also matches ``/``: ``/bot1*/cmd_vel``, ``/*/leds``); ``/clock`` and
    ``/swarm/state`` are always recorded. ``world``, when given, is stored in the bag so that
    a replay needs nothing else. ``compress`` turns on zstd chunk compression (MCAP's own,
    read by ros2 bag, Foxglove and rosbags).

    Leaving the ``with`` block closes the bag, also on an exception or a KeyboardInterrupt:
    a run stopped early leaves a bag with the ticks written so far. A run killed outright leaves
    the ticks up to the last ``flush`` (module docstring).
    """

    def __init__(self, path: str | os.PathLike, *, robot_names: Iterable[str], tick_s: float,
                 topics_globs: Iterable[str] = (), world: Optional["World"] = None,
                 compress: bool = True):
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        self.path = Path(path)
        self.robot_names = list(robot_names)
        try:
            seconds = float(tick_s)
        except (TypeError, ValueError):
            seconds = math.nan
        if not (math.isfinite(seconds) and seconds > 0):
            raise ValueError(f"tick_s must be a positive number of seconds (got {tick_s!r})")
        self.tick_s = seconds
        self.tick_ns = round(self.tick_s * _NS_PER_S)
        self._globs = TopicGlobs(topics_globs)
        self.topics_globs = self._globs.topics_globs
        if self.path.exists():
            raise RecordingError(f"{self.path}: already exists; a recording needs a new directory")
        self._typestore = _new_typestore()
        self._writer = Writer(self.path, version=_BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._custom: dict[str, str] = {CUSTOM_PREFIX + "robot_names": json.dumps(self.robot_names),
                                        CUSTOM_PREFIX + "tick_s": repr(self.tick_s)}
        if world is not None:
            from composed_sim.world.loader import dump_world
            self._custom[CUSTOM_PREFIX + "world"] = dump_world(world)
        try:
            self._writer.open()
        except Exception as e:
            raise RecordingError(f"{self.path}: cannot create the recording: {e}") from None
        _check_flushable(self._writer.storage)
        self.mcap_path: Path = self._writer.storage.path
        self._closed = False
        self._durable_bytes = 0                     # the MCAP file's size at its last flush
        self._next_flush = 2                        # clocks written; the first flush once tick 1 begins
        self._flushed_at = time.monotonic()
        self._sync()
        self._keep_unfinished()
        _fsync_directory(self.path)                 # the new files' names survive a power loss too
        self._busy = False                          # inside a write: see close_if_idle
        self._connections: dict[str, Any] = {}     # topic -> rosbags Connection
        self._qos = _qos_profiles()
        self.ticks_written = 0
        self.counts: dict[str, int] = {}            # topic -> messages written
        types = self._typestore.types
        self._Clock, self._Time = types[CLOCK_TYPE], types["builtin_interfaces/msg/Time"]
        self._Header, self._Cloud = types["std_msgs/msg/Header"], types[SWARM_STATE_TYPE]
        field = types["sensor_msgs/msg/PointField"]
        kinds = {"f8": field.FLOAT64, "u4": field.UINT32}
        self._fields = [field(name=name, offset=STATE_DTYPE.fields[name][1],
                              datatype=kinds[STATE_DTYPE.fields[name][0].str[1:]], count=1)
                        for name in STATE_DTYPE.names]
        self._points = np.zeros(len(self.robot_names), dtype=STATE_DTYPE)
        self._points["id"] = np.arange(len(self.robot_names))
        self._connection(CLOCK_TOPIC, CLOCK_TYPE)
        self._connection(SWARM_STATE_TOPIC, SWARM_STATE_TYPE)

    # -- context manager --

    def __enter__(self) -> "BagRecorder":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        try:                    # an interrupted run still leaves a readable bag
            self.close()
        except Exception:       # noqa: BLE001 - the original error matters more
            self._abort()

    @property
    def closed(self) -> bool:
        return self._closed

    # -- topics --

    def wants(self, topic: str) -> bool:
        """True when ``topic`` matches one of the globs; the answer is cached per topic."""
        return self._globs.wants(topic)

    def set_custom(self, key: str, value: str) -> None:
        """Add a ``composed_sim.<key>`` entry to the bag's custom_data (written at close, and to
        ``UNFINISHED`` at once)."""
        self._custom[CUSTOM_PREFIX + key] = str(value)
        self._keep_unfinished()

    # -- writing --

    def write_clock(self, tick: int, stamp_ns: Optional[int] = None) -> None:
        """/clock for ``tick``; ``stamp_ns`` defaults to ``tick * tick_ns``."""
        ns = tick * self.tick_ns if stamp_ns is None else int(stamp_ns)
        msg = self._Clock(clock=self._stamp(ns))
        self._write(CLOCK_TOPIC, ns, self._typestore.serialize_cdr(msg, CLOCK_TYPE))

    def write_swarm_state(self, stamp_ns: int, positions: np.ndarray, headings: np.ndarray,
                          led_colors: Optional[np.ndarray] = None) -> None:
        """/swarm/state: positions [n, 2] m, headings [n] rad, led_colors [n, L, 3] or [n, 3]
        uint8 (None: no LED lit). n must equal ``len(robot_names)``."""
        n = len(self.robot_names)
        p, h = checked_poses(n, positions, headings)
        pts = self._points
        pts["x"], pts["y"], pts["yaw"] = p[:, 0], p[:, 1], h
        if led_colors is None:
            pts["rgb"] = 0
        else:
            colors = display_colors(led_colors)
            if colors.shape != (n, 3):
                raise ValueError(f"led_colors must hold {n} robots, got shape {np.shape(led_colors)}")
            pts["rgb"] = pack_rgb(colors)
        ns = int(stamp_ns)
        msg = self._Cloud(header=self._Header(stamp=self._stamp(ns), frame_id=FRAME_ID),
                          height=1, width=n, fields=self._fields, is_bigendian=False,
                          point_step=STATE_DTYPE.itemsize, row_step=STATE_DTYPE.itemsize * n,
                          data=pts.view(np.uint8), is_dense=True)
        self._write(SWARM_STATE_TOPIC, ns, self._typestore.serialize_cdr(msg, SWARM_STATE_TYPE))

    def write_message(self, topic: str, msg: Any, stamp_ns: int) -> bool:
        """Record an rclpy message on ``topic`` if the globs select it; returns whether it did.

        Ask ``wants(topic)`` first to skip building messages nobody records.
        """
        if not self.wants(topic):
            return False
        from rclpy.serialization import serialize_message
        self._write(topic, int(stamp_ns), serialize_message(msg), ros_type_name(msg))
        return True

    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int, *,
                         always: bool = False) -> bool:
        """Like ``write_message`` for an already CDR-serialised message of type ``msgtype``;
        ``always``: whatever the globs (the run's own global topics)."""
        if not (always or self.wants(topic)):
            return False
        self._write(topic, int(stamp_ns), data, msgtype)
        return True

    def flush(self) -> None:
        """End the chunk in progress and sync the MCAP file to disk: a process killed after this
        leaves everything written so far readable. Done by itself every FLUSH_EVERY_TICKS ticks
        or FLUSH_EVERY_S seconds, right after a tick's /clock: a flushed file always holds the
        /clock of the tick after its last complete one (what ``bag repair`` cuts at)."""
        if self._closed:
            raise RecordingError(f"{self.path}: the recording is closed")
        self._busy = True
        try:
            self._sync(end_chunk=True)
        finally:
            self._busy = False
        self._next_flush = self.ticks_written + FLUSH_EVERY_TICKS
        self._flushed_at = time.monotonic()

    def close(self) -> None:
        """Write the MCAP index and metadata.yaml; the bag is complete afterwards. Idempotent."""
        if self._closed:
            return
        self._closed = True
        for key, value in self._custom.items():
            self._writer.set_custom_data(key, value)
        # The ticks simulated, as summary.json counts them: the last tick (tick 0 is the start).
        self._writer.set_custom_data(CUSTOM_PREFIX + "ticks", str(max(self.ticks_written - 1, 0)))
        try:
            self._writer.close()
        except OSError as e:
            self._fail(e)
        (self.path / UNFINISHED).unlink(missing_ok=True)

    def close_if_idle(self) -> bool:
        """Close unless a write is under way; for a signal handler about to end the process
        (``os._exit``), which would otherwise leave a bag without index and metadata.yaml.
        Returns whether the bag is closed."""
        if self._busy:
            return False
        self.close()
        return True

    # -- internals --

    def _abort(self) -> None:
        self._closed = True
        self._writer.abort()

    def _sync(self, *, end_chunk: bool = False) -> None:
        """Everything written so far onto the disk, up to a complete record; ``end_chunk``: the
        chunk in progress too."""
        storage = self._writer.storage
        try:
            if end_chunk and storage.chunk.bio.tell():  # an empty chunk would be a record with no messages
                storage.close_chunk()
            storage.bio.flush()
            os.fsync(storage.bio.fileno())
        except OSError as e:
            self._fail(e)
        self._durable_bytes = storage.bio.tell()

    def _fail(self, error: OSError):
        """A write failed (a full disk): cut the MCAP file back to its last flush, where it ends
        on a complete record and stays repairable, stop recording, and raise the error naming
        the file."""
        self._closed = True
        storage, self._writer.storage = self._writer.storage, None
        if storage is not None:                     # else the MCAP file was complete: metadata.yaml failed
            try:
                storage.bio.close()                 # closes the file even when its buffer cannot be written
            except OSError:
                pass
            os.truncate(self.mcap_path, self._durable_bytes)
        raise OSError(error.errno or errno.EIO, error.strerror or str(error),
                      str(error.filename or self.mcap_path)) from None

    def _keep_unfinished(self) -> None:
        """The custom_data on disk beside the MCAP file until ``close``: what repairs a bag
        whose writer was killed."""
        import yaml
        part = self.path / (UNFINISHED + ".part")
        try:
            with open(part, "w", encoding="utf-8") as f:
                yaml.safe_dump(self._custom, f, sort_keys=False)
                f.flush()
                os.fsync(f.fileno())
            os.replace(part, self.path / UNFINISHED)
        except OSError as e:
            part.unlink(missing_ok=True)
            raise OSError(e.errno, e.strerror, str(self.path / UNFINISHED)) from None

    def _stamp(self, ns: int):
        return self._Time(sec=ns // _NS_PER_S, nanosec=ns % _NS_PER_S)

    def _connection(self, topic: str, msgtype: str):
        conn = self._connections.get(topic)
        if conn is None:
            definition = message_definition(msgtype)
            conn = self._writer.add_connection(topic, msgtype, msgdef=definition[0],
                                               rihs01=definition[1], offered_qos_profiles=self._qos)
            self._connections[topic] = conn
            self.counts[topic] = 0
        elif conn.msgtype != msgtype:
            raise RecordingError(f"{topic}: recorded as {conn.msgtype}, cannot also hold {msgtype}")
        return conn

    def _write(self, topic: str, ns: int, data: bytes, msgtype: Optional[str] = None) -> None:
        if self._closed:
            raise RecordingError(f"{self.path}: the recording is closed")
        self._busy = True
        try:
            conn = self._connections[topic] if msgtype is None else self._connection(topic, msgtype)
            try:
                self._writer.write(conn, ns, data)      # rosbags writes a chunk out when it exceeds 1 MiB
            except OSError as e:
                self._fail(e)
            self.counts[topic] += 1
        finally:
            self._busy = False
        if topic == CLOCK_TOPIC:
            self.ticks_written += 1
            if self.ticks_written >= self._next_flush or time.monotonic() - self._flushed_at >= FLUSH_EVERY_S:
                self.flush()


def _check_flushable(storage) -> None:
    """``flush`` ends rosbags' chunk in progress with its MCAP writer's own ``close_chunk``; a
    rosbags without it would leave recordings that a kill makes unreadable."""
    if not all(hasattr(storage, a) for a in ("close_chunk", "bio", "chunk")):
        from importlib.metadata import version
        raise RecordingError(f"rosbags {version('rosbags')}: its MCAP writer has no close_chunk/bio/chunk, "
                             f"which flushing a recording needs (written for rosbags 0.11)")


def _fsync_directory(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


# --- reading -----------------------------------------------------------------------------

@dataclass
class Recording:
    """A recording's swarm state, Trajectories-like (``positions``, ``headings``, ``names``)."""
    names: list[str]
    tick_s: float
    stamps_ns: np.ndarray       # [T] sim time of each swarm state
    positions: np.ndarray       # [T, n, 2] m
    headings: np.ndarray        # [T, n] rad
    led_colors: np.ndarray      # [T, n, 3] uint8 display colours (0 = no LED lit)
    world: Optional["World"]    # the world stored at record time, if any
    topics: dict[str, tuple[str, int]]    # topic -> (message type, message count)
    executor: Optional[str] = None        # the executor that ran the recorded run, if stored

    @property
    def ticks(self) -> np.ndarray:
        """[T] tick number of each swarm state."""
        return np.rint(self.stamps_ns / (self.tick_s * _NS_PER_S)).astype(int)

    @property
    def ticks_done(self) -> int:
        """The last recorded tick (0 for an empty bag)."""
        return int(self.ticks[-1]) if len(self.stamps_ns) else 0


def read_recording(path: str | os.PathLike) -> Recording:
    """Read a bag written by ``BagRecorder``: the swarm state of every tick and what it stored."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    custom = _custom_data(path)
    typestore = _new_typestore()
    try:
        with Reader(path) as reader:
            topics = {name: (info.msgtype, info.msgcount) for name, info in reader.topics.items()}
            conns = [c for c in reader.connections if c.topic == SWARM_STATE_TOPIC]
            stamps, clouds = [], []
            for conn, ns, raw in reader.messages(connections=conns):
                msg = typestore.deserialize_cdr(raw, conn.msgtype)
                stamps.append(ns)
                clouds.append(_decode_state(msg, path, ns))
    except RecordingError:
        raise
    except Exception as e:    # noqa: BLE001 - rosbags' reader errors and file-system errors alike
        raise RecordingError(f"{path}: not a readable rosbag2 recording: {e}") from None
    names = json.loads(custom[CUSTOM_PREFIX + "robot_names"]) if CUSTOM_PREFIX + "robot_names" in custom else \
        [f"robot{i}" for i in range(len(clouds[0]) if clouds else 0)]
    n = len(names)
    if any(len(c) != n for c in clouds):
        raise RecordingError(f"{path}: a swarm state does not hold the {n} recorded robots")
    tick_s = float(custom.get(CUSTOM_PREFIX + "tick_s", "nan"))
    if not math.isfinite(tick_s):
        tick_s = (stamps[1] - stamps[0]) / _NS_PER_S if len(stamps) > 1 else 0.1
    order = np.argsort(stamps, kind="stable")
    pts = np.stack([clouds[i] for i in order]) if clouds else np.zeros((0, n), STATE_DTYPE)
    world = None
    if CUSTOM_PREFIX + "world" in custom:
        import yaml
        from composed_sim.world.loader import world_from_dict
        world = world_from_dict(yaml.safe_load(custom[CUSTOM_PREFIX + "world"]),
                                source=f"{path}/metadata.yaml custom_data {CUSTOM_PREFIX}world")
    return Recording(names=names, tick_s=tick_s,
                     stamps_ns=np.asarray(stamps, dtype=np.int64)[order],
                     positions=np.stack([pts["x"], pts["y"]], axis=-1),
                     headings=pts["yaw"].copy(), led_colors=unpack_rgb(pts["rgb"]),
                     world=world, topics=topics, executor=custom.get(CUSTOM_PREFIX + "executor"))


def read_swarm_states(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(stamps_ns [T], positions [T, n, 2], headings [T, n], led_colors [T, n, 3] uint8)."""
    r = read_recording(path)
    return r.stamps_ns, r.positions, r.headings, r.led_colors


def _custom_data(path: Path) -> dict[str, str]:
    import yaml
    meta = path / "metadata.yaml"
    try:
        data = yaml.safe_load(meta.read_text(encoding="utf-8"))
        return dict(data["rosbag2_bagfile_information"].get("custom_data") or {})
    except FileNotFoundError:
        hint = f"; its run was killed before closing it: composed-sim bag repair {path}" \
            if (path / UNFINISHED).exists() else "; not a rosbag2 directory"
        raise RecordingError(f"{path}: no metadata.yaml{hint}") from None
    except Exception as e:    # noqa: BLE001
        raise RecordingError(f"{meta}: unreadable rosbag2 metadata: {e}") from None


def _decode_state(msg: Any, path: Path, ns: int) -> np.ndarray:
    layout = [(f.name, f.offset, f.datatype) for f in msg.fields]
    expected = [(name, STATE_DTYPE.fields[name][1], None) for name in STATE_DTYPE.names]
    if [(a, b) for a, b, _ in layout] != [(a, b) for a, b, _ in expected] \
            or msg.point_step != STATE_DTYPE.itemsize or msg.is_bigendian:
        raise RecordingError(f"{path}: {SWARM_STATE_TOPIC} at {ns} ns: unexpected point layout "
                             f"{[(a, b) for a, b, _ in layout]} (point_step {msg.point_step})")
    return np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=STATE_DTYPE,
                         count=msg.width * msg.height)
