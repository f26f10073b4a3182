"""Sensor messages handed over in process with their readings already decoded.

A simulator node encodes each robot's sensor messages from its group's readings, and the robot's
controller (``SwarmController``, through its device's reader) decodes them back into arrays. In
one process that round trip is the host's work twice over (decoding alone was a tenth of the
host's cost per robot-tick: docs/speed.md). Where a topic's messages go in process (ros/in_process.py)
to subscriptions that take the bytes (a controller's readers; a plain node's subscription gets
a message object instead), its device publisher therefore also decodes the whole group's messages
at once, with the numpy operations its reader applies to one message, over the very
float32 values the bytes carry, and leaves each message's part of that batch here, under the
message: the reader that gets the message takes it instead of decoding.

Nothing else changes: the messages are the same bytes to every subscription, recording and
transport (through DDS the reader decodes them: the same reading, bit for bit, which the tests
check device by device and by whole runs with and without the in-process path). The first reader
of a message takes its reading; any other reader of the same message decodes its own copy, as
readers of a message from DDS each get theirs.

The readings are kept by the messages' identity, for the messages of the newest tick only (a
tick's messages are taken before the next tick is published; one taken later is decoded), and
the messages are held until then, so that no other object can take an identity over. No object
is made per message: thousands of short-lived objects per tick that outlive a young-generation
collection (they wait in the inboxes) were promoted into the collector's old generations, and
full collections then walked every robot's nodes (docs/speed.md).
"""
from __future__ import annotations

from typing import Callable, Optional, Sequence

Batch = Callable[[int], object]      # k → the reading of the batch's k-th message

_stamp_ns: Optional[int] = None      # the tick whose messages are kept
_batches: dict[int, Batch] = {}      # id(message) → its batch …
_places: dict[int, int] = {}         # … and its place in it
_messages: list[Sequence[bytes]] = []   # holds the tick's messages: their identities stay theirs


def hand_readings(messages: Sequence[bytes], batch: Batch, places: Sequence[int], stamp_ns: int) -> None:
    """The j-th message's reading is ``batch(places[j])``; the messages are of tick ``stamp_ns``."""
    global _stamp_ns
    if stamp_ns != _stamp_ns:
        _batches.clear()
        _places.clear()
        _messages.clear()
        _stamp_ns = stamp_ns
    before = len(_places)
    for data, k in zip(messages, places):
        key = id(data)
        _batches[key] = batch
        _places[key] = k
    _messages.append(messages)
    if len(_places) != before + len(messages):   # one object sent twice: its reading is ambiguous
        for data in messages:
            _batches.pop(id(data), None)
            _places.pop(id(data), None)


def take_reading(data) -> Optional[object]:
    """A reader's first step: the reading handed with ``data``, the first time (else None: decode
    the bytes)."""
    k = _places.pop(id(data), None)
    return None if k is None else _batches.pop(id(data))(k)
