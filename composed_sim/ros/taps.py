"""Which per-robot topics a recording wants, and a tap that holds their messages for later.

A worker process's simulator nodes tap into a ``TapBuffer``; the buffer's messages travel to the
main process with the tick's answers and are written to the bag there (hosts/workers/worker_host.py).
"""
from __future__ import annotations

import fnmatch
import re
from typing import Iterable, Protocol


class MessageTap(Protocol):
    """Where the simulator node hands the messages of the topics it ``wants`` (robot_taps.py)."""
    def wants(self, topic: str) -> bool: ...
    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> object: ...


class TopicGlobs:
    """``fnmatch`` patterns on full topic names (``*`` also matches ``/``: ``/bot1*/cmd_vel``)."""

    def __init__(self, globs: Iterable[str] = ()):
        self.topics_globs = list(globs)
        self._patterns = [re.compile(fnmatch.translate(g)) for g in self.topics_globs]
        self._wanted: dict[str, bool] = {}

    def wants(self, topic: str) -> bool:
        """True when ``topic`` matches one of the globs; the answer is cached per topic."""
        hit = self._wanted.get(topic)
        if hit is None:
            hit = self._wanted[topic] = any(p.match(topic) for p in self._patterns)
        return hit


class TapBuffer(TopicGlobs):
    """A ``MessageTap`` that keeps the messages until ``drain``."""

    def __init__(self, globs: Iterable[str] = ()):
        super().__init__(globs)
        self._messages: list[tuple[str, str, bytes, int]] = []

    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> bool:
        self._messages.append((topic, msgtype, bytes(data), stamp_ns))
        return True

    def drain(self) -> list[tuple[str, str, bytes, int]]:
        """(topic, type, serialized message, stamp ns) of every message since the last drain."""
        out, self._messages = self._messages, []
        return out


class Taps:
    """Several message taps as one (a recording and a live viewer)."""

    def __init__(self, taps: Iterable):
        self.taps = list(taps)
        self.topics_globs = [g for tap in self.taps for g in tap.topics_globs]

    def wants(self, topic: str) -> bool:
        return any(tap.wants(topic) for tap in self.taps)

    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> bool:
        wrote = False
        for tap in self.taps:
            if tap.wants(topic):
                wrote = tap.write_serialized(topic, msgtype, data, stamp_ns) or wrote
        return wrote
