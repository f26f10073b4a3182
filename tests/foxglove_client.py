"""A Foxglove WebSocket client written from the protocol's published spec (foxglove/ws-protocol,
subprotocol ``foxglove.websocket.v1``), with the ``websockets`` package: what the Foxglove app
does when it opens a live connection, minus the drawing. Like the app it also offers
``foxglove.sdk.v1``, the name under which foxglove-sdk 0.30's server speaks the same protocol
(it accepts no other).

Server → client: JSON text frames ``serverInfo``, ``advertise`` {channels: [{id, topic, encoding,
schemaName, schema, schemaEncoding}]}; binary frames, first byte the opcode: 1 = message data
(u32 subscription id, u64 log time ns, payload), 2 = time (u64 ns). Client → server: JSON
``subscribe`` {subscriptions: [{id, channelId}]}.
"""
from __future__ import annotations

import json
import socket
import struct
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]
MESSAGE_DATA, TIME = 1, 2


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def open_connection(port: int, timeout_s: float = 60.0):
    """Connect to ws://127.0.0.1:port, retrying while the run starts up."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS, open_timeout=5)
        except (OSError, TimeoutError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def channels(ws, topics: set[str], timeout_s: float = 30.0) -> dict[str, dict]:
    """Read ``advertise`` ops until every topic in ``topics`` is advertised: {topic: channel}."""
    found: dict[str, dict] = {}
    deadline = time.monotonic() + timeout_s
    while not topics <= found.keys():
        frame = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
        if isinstance(frame, str):
            op = json.loads(frame)
            if op["op"] == "advertise":
                found.update({c["topic"]: c for c in op["channels"]})
    return found


def subscribe(ws, channel_ids: list[int]) -> dict[int, int]:
    """Subscribe to each channel, one op each, in order: {subscription id: channel id}."""
    subs = {}
    for sub_id, channel_id in enumerate(channel_ids, start=1):
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel_id}]}))
        subs[sub_id] = channel_id
    return subs


def receive_until_closed(ws, timeout_s: float = 120.0, on_message=None) -> dict[int, list[tuple[int, bytes]]]:
    """Every message data frame until the server closes: {subscription id: [(log time ns, payload)]}.
    ``on_message(count)`` is called after each one (to misbehave in the middle of a run)."""
    got: dict[int, list[tuple[int, bytes]]] = {}
    count = 0
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            frame = ws.recv(timeout=deadline - time.monotonic())
            if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                got.setdefault(sub_id, []).append((log_time, frame[13:]))
                count += 1
                if on_message is not None:
                    on_message(count)
    except ConnectionClosed:
        pass
    return got
