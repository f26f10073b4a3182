"""Writing a run's recording as a rosbag2 directory (MCAP storage, sim-time stamps) that survives
a kill: every FLUSH_EVERY_TICKS ticks or FLUSH_EVERY_S, whichever comes first, the chunk in
progress is ended and the file synced (``flush``), so the MCAP file ends on a complete record;
``UNFINISHED`` beside it marks a recording never closed (``composed-sim bag repair``, repair.py)."""
from __future__ import annotations

import errno
import json
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Optional

import numpy as np

from composed_sim.devices.common.poses import checked_poses
from composed_sim.outputs.recording.messages import (CLOCK_TOPIC, CLOCK_TYPE, CUSTOM_PREFIX, NS_PER_S, STATE_DTYPE,
                                                     SWARM_STATE_TOPIC, SWARM_STATE_TYPE, UNFINISHED, FRAME_ID,
                                                     RecordingError, message_definition, new_typestore, pack_rgb,
                                                     ros_type_name)
from composed_sim.ros.taps import TopicGlobs
from composed_sim.world.robot_models import display_colors

if TYPE_CHECKING:
    from composed_sim.world.schema import World

BAG_VERSION = 9            # the rosbag2 metadata version of ROS 2 Jazzy
# How much a killed run may lose from its recording: each flush ends a chunk (so compression
# works on smaller chunks) and syncs the file (docs/faults.md gives the cost).
FLUSH_EVERY_TICKS = 50
FLUSH_EVERY_S = 5.0


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
        self.tick_ns = round(self.tick_s * NS_PER_S)
        self._globs = TopicGlobs(topics_globs)
        self.topics_globs = self._globs.topics_globs
        if self.path.exists():
            raise RecordingError(f"{self.path}: already exists; a recording needs a new directory")
        self._typestore = new_typestore()
        self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._custom: dict[str, str] = {CUSTOM_PREFIX + "robot_names": json.dumps(self.robot_names),
                                        CUSTOM_PREFIX + "tick_s": repr(self.tick_s)}
        if world is not None:
            from composed_sim.world.loader import dump_world
            self._custom[CUSTOM_PREFIX + "world"] = dump_world(world)
        try:
            self._writer.open()
        except Exception as e:    # noqa: BLE001 - rosbags raises its own and the file system's errors
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
        return self._Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)

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


def _qos_profiles():
    """The contract's QoS (reliable, keep last 10, volatile), for `ros2 bag play`."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    never = QosTime(sec=0, nsec=0)
    return [Qos(history=QosHistory.KEEP_LAST, depth=10, reliability=QosReliability.RELIABLE,
                durability=QosDurability.VOLATILE, deadline=never, lifespan=never,
                liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
                avoid_ros_namespace_conventions=False)]


