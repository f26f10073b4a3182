"""Serve a run live over the Foxglove WebSocket protocol (``--foxglove [HOST:]PORT``).

The Foxglove app (or any client of the protocol, ``foxglove.websocket.v1``) connects to the main
process and needs no ROS install: every channel carries ROS 2 messages as CDR bytes with their
``ros2msg`` schema, which the app decodes itself, the very bytes a ``--record`` bag holds.

  /swarm/markers   visualization_msgs/msg/MarkerArray  the scene, once per tick (live/markers.py)
  /clock           rosgraph_msgs/msg/Clock             once per tick
  per-robot topics their contract types                 those matching ``--foxglove-topics``
  run-wide topics  their nodes' types (users' own too)  those matching ``--foxglove-topics``, advertised
                                                        once a node first publishes on them

Every message is logged at its sim time (tick k at k * tick_s), as in a bag, and the server
broadcasts that time, so the app's clock is the simulation's. The server (the ``foxglove-sdk``
package, Rust) runs in its own threads: a viewer that connects, leaves, connects twice or sends
garbage is its business, never the tick loop's. A channel nobody subscribed to costs one set
lookup per tick: no bytes are built for it.
"""
from __future__ import annotations

import struct
import threading
import time
from typing import Iterable, Optional

import foxglove
import psutil
from foxglove.websocket import Capability

from composed_sim.core.simulation import Simulation
from composed_sim.live import DEFAULT_FOXGLOVE_HOST
from composed_sim.live.observers import Scene
from composed_sim.outputs.recording import CLOCK_TYPE, message_definition
from composed_sim.ros.global_topics import CLOCK_TOPIC, SWARM_MARKERS_TOPIC
from composed_sim.live.markers import MARKERS_TYPE
from composed_sim.ros.taps import TopicGlobs

DRAIN_S = 1.0        # at the end of a watched run: time for the viewers to receive the last ticks
_CDR_HEADER = b"\x00\x01\x00\x00"        # little-endian CDR encapsulation


class FoxgloveError(Exception):
    """The server cannot start; the message names the address and, if known, who holds it."""


def parse_address(text: str) -> tuple[str, int]:
    """'[HOST:]PORT' → (host, port); raises ValueError naming the value."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise ValueError(f"{text!r}: not [HOST:]PORT with a port in 0..65535")
    return host or DEFAULT_FOXGLOVE_HOST, number


def port_holder(port: int) -> Optional[str]:
    """'python3 (pid 123)' for the process listening on ``port``, if this user may know it."""
    try:
        for conn in psutil.net_connections(kind="inet"):
            if conn.laddr and conn.laddr.port == port and conn.status == psutil.CONN_LISTEN and conn.pid:
                return f"{psutil.Process(conn.pid).name()} (pid {conn.pid})"
    except (psutil.Error, OSError):
        pass
    return None


class _Subscriptions:
    """Which channels have at least one subscribed client (the server calls from its threads)."""

    def __init__(self):
        self._clients: dict[int, set[int]] = {}     # channel id -> client ids
        self._lock = threading.Lock()
        self.scene_id: Optional[int] = None
        self.viewer = threading.Event()             # set once someone subscribed to the scene

    def on_subscribe(self, client, channel) -> None:
        with self._lock:
            self._clients.setdefault(channel.id, set()).add(client.id)
        if channel.id == self.scene_id:
            self.viewer.set()

    def on_unsubscribe(self, client, channel) -> None:
        with self._lock:
            self._clients.get(channel.id, set()).discard(client.id)

    def watched(self, channel_id: int) -> bool:
        return bool(self._clients.get(channel_id))

    def anyone(self) -> bool:
        with self._lock:
            return any(self._clients.values())


class FoxgloveServer:
    """A tick observer serving the scene and /clock, and a message tap serving the selected
    per-robot topics (``topics``: {topic: message type} of this run, ``globs`` select among them)."""

    def __init__(self, scene: Scene, address: tuple[str, int], topics: dict[str, str],
                 globs: Iterable[str] = (), *, wait_for_viewer_s: float = 0.0, name: str = "composed_sim"):
        host, port = address
        self.scene = scene
        self.tick_ns = scene.tick_ns
        self.wait_for_viewer_s = wait_for_viewer_s
        self._subscriptions = _Subscriptions()
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context,
                                                 capabilities=[Capability.Time],
                                                 server_listener=self._subscriptions,
                                                 supported_encodings=["cdr"])
        except Exception as e:     # noqa: BLE001 - the SDK raises its own error types for a bind failure
            holder = port_holder(port)
            raise FoxgloveError(f"--foxglove {host}:{port}: cannot serve there "
                                f"({f'port {port} is held by {holder}' if holder else e})") from None
        self.port = self._server.port
        self._globs = TopicGlobs(globs)
        self.topics_globs = self._globs.topics_globs      # the workers tap these (hosts/workers/worker_host.py)
        self._scene_channel = self._channel(SWARM_MARKERS_TOPIC, MARKERS_TYPE)
        self._subscriptions.scene_id = self._scene_channel.id()
        self._clock_channel = self._channel(CLOCK_TOPIC, CLOCK_TYPE)
        self._robot_channels = {topic: self._channel(topic, msgtype) for topic, msgtype in topics.items()
                                if self._globs.wants(topic)}
        self._advertising = threading.Lock()
        self._known = frozenset(topics)      # a topic outside them is a run-wide one (hosting/run_wide/relay.py)

    def _channel(self, topic: str, msgtype: str) -> foxglove.Channel:
        msgdef, _ = message_definition(msgtype)
        schema = foxglove.Schema(name=msgtype, encoding="ros2msg", data=msgdef.encode())
        return foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self._context)

    # -- tick observer --

    def on_tick(self, sim: Simulation) -> None:
        if sim.tick == 0 and self.wait_for_viewer_s > 0:
            # Released by a subscription to the scene: a client that subscribes to the scene
            # last gets tick 0 on every channel it asked for.
            self._subscriptions.viewer.wait(self.wait_for_viewer_s)
        stamp_ns = sim.tick * self.tick_ns
        self._server.broadcast_time(stamp_ns)
        if self._subscriptions.watched(self._clock_channel.id()):
            sec, nanosec = divmod(stamp_ns, 1_000_000_000)
            self._clock_channel.log(_CDR_HEADER + struct.pack("<iI", sec, nanosec), log_time=stamp_ns)
        if self._subscriptions.watched(self._scene_channel.id()):
            self._scene_channel.log(self.scene.cdr(sim), log_time=stamp_ns)

    # -- message tap (per-robot topics, from the simulator nodes or the workers) --

    def wants(self, topic: str) -> bool:
        return topic in self._robot_channels or (topic not in self._known and self._globs.wants(topic))

    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> bool:
        channel = self._robot_channels.get(topic)
        if channel is None and self.wants(topic):      # a run-wide topic's first message: advertised now
            with self._advertising:     # once: taps of several threads (a viewer subscribes to the first)
                channel = self._robot_channels.get(topic)
                if channel is None:
                    channel = self._robot_channels[topic] = self._channel(topic, msgtype)
        if channel is None or not self._subscriptions.watched(channel.id()):
            return False
        channel.log(bytes(data), log_time=int(stamp_ns))
        return True

    def close(self) -> None:
        """Stop serving. Stopping drops what the server has not sent yet; a run ends faster than
        a viewer on a slow link reads, so a watched run gives it DRAIN_S to get the last ticks."""
        if self._subscriptions.anyone():
            time.sleep(DRAIN_S)
        self._server.stop()
