"""The watch for another simulator in a run's ROS domain: another publisher of /clock.

A simulator that joined the domain after the run claimed it (or that the claim's probe missed,
docs/faults.md) sends its sensors to this run's controllers, so the run is no longer its own.
"""
from __future__ import annotations

import time
from typing import Optional

from rclpy.node import Node

from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import NODE_NAME_UNKNOWN, graph_gid, publisher_text

# How often the watch asks the ROS graph for another /clock publisher: a count in its
# participant's graph cache, cheap but not free (docs/speed.md).
CLOCK_WATCH_S = 1.0


class ClockWatch:
    """Asks ``node``'s graph for a /clock publisher other than ``own_gid`` (the node's own)."""

    def __init__(self, node: Node, own_gid: bytes):
        self._node, self._own_gid = node, own_gid
        self._next_look = 0.0
        self._other_seen_at: dict[bytes, float] = {}     # another /clock publisher's GID → first seen, not named

    def another_simulator(self) -> Optional[str]:
        """Another publisher of /clock, as ``node /x (publisher GID …)``, or None. Asks the graph at
        most once per CLOCK_WATCH_S (and, for up to a second, every 50 ms while the graph has not
        named the other's node yet)."""
        now = time.monotonic()
        if now < self._next_look:
            return None
        self._next_look = now + CLOCK_WATCH_S
        if self._node.count_publishers(c.CLOCK_TOPIC) <= 1:
            return None
        other = next((info for info in self._node.get_publishers_info_by_topic(c.CLOCK_TOPIC)
                      if graph_gid(info) != self._own_gid), None)
        if other is None:
            return None
        if other.node_name == NODE_NAME_UNKNOWN and now < self._other_seen_at.setdefault(graph_gid(other), now) + 1.0:
            self._next_look = now + 0.05     # its node's name comes a moment after the endpoint
            return None
        return publisher_text(other)
