"""A simulator node's side of a message tap (ros/taps.py): which of its robots' topics the tap
wants, and their messages handed to it, from any thread (answers arrive on executor threads)."""
from __future__ import annotations

import threading
from typing import Optional, Sequence

from rclpy.serialization import serialize_message

from composed_sim.ros import contract as c
from composed_sim.ros.taps import MessageTap


class RobotTaps:
    def __init__(self, names: list[str]):
        self._names = names
        self.tap: Optional[MessageTap] = None
        self._lock = threading.Lock()
        self._tapped: dict[str, list[bool]] = {}

    def set(self, tap: MessageTap) -> None:
        self.tap = tap
        self._tapped = {topic.name: [tap.wants(c.topic_name(name, topic)) for name in self._names]
                        for topic in c.TOPICS.values()}

    def wants(self, topic: c.Topic, i: int) -> bool:
        """Is robot i's ``topic`` tapped?"""
        return self.tap is not None and self._tapped[topic.name][i]

    def message(self, topic: c.Topic, i: int, data, stamp_ns: int, msg_type: Optional[type] = None) -> None:
        """Hand robot i's message on ``topic`` to the tap if it wants it. ``data``: the message's
        bytes, or the message; ``msg_type``: when not the topic's."""
        if self.wants(topic, i):
            if not isinstance(data, bytes):
                data = serialize_message(data)
            self.write(c.topic_name(self._names[i], topic), c.type_name(msg_type) if msg_type else topic.type_name,
                       data, stamp_ns)

    def messages(self, topic: c.Topic, rows: Sequence[int], messages: Sequence, stamp_ns: int) -> None:
        """``message`` for each of robots ``rows`` (``messages[j]`` robot ``rows[j]``'s)."""
        if self.tap is not None:
            for i, data in zip(rows, messages):
                self.message(topic, i, data, stamp_ns)

    def write(self, topic: str, type_name: str, data: bytes, stamp_ns: int) -> None:
        with self._lock:
            self.tap.write_serialized(topic, type_name, data, stamp_ns)
