"""Calls from other processes to the services a host serves in process.

A tool (``ros2 param set``, ``ros2 service call``) or another program's node calls a hosted node's
service through DDS. The host takes such requests at the start of each tick, where they are
served in the walk's order like the others, so that a run does not depend on when they arrived;
an in-process service that a client elsewhere wants (a node's parameter services) gets its DDS
endpoint once that client is on the ROS graph (``ServiceDirectory.find_outside_clients``).
"""
from __future__ import annotations

from typing import Callable, Collection, Optional

from rclpy.node import Node

from composed_sim.hosting.calls.directory import ServiceDirectory
from composed_sim.ros.rcl_graph import GraphChanges


class OutsideCalls:
    """One directory's calls from other processes. ``graph_changed()``: has the ROS graph changed
    since the last look (the first look: yes)? ``robots``: the run's robots, whose nodes are all
    the run's own."""

    def __init__(self, directory: ServiceDirectory, robots: Collection[str], graph_changed: Callable[[], bool],
                 graph: Optional[GraphChanges] = None):
        self._directory = directory
        self._namespaces = frozenset(f"/{name}" for name in robots)
        self._graph_changed = graph_changed
        self._graph = graph

    @classmethod
    def watching(cls, directory: ServiceDirectory, robots: Collection[str], node: Node) -> "OutsideCalls":
        """Watching the graph of ``node``'s participant: only where nothing else in the process
        watches it (a wait on the graph's guard condition consumes its triggers)."""
        graph = GraphChanges([node])
        return cls(directory, robots, graph.poll(0), graph)

    def take(self) -> None:
        """At a tick's start: the requests from other processes, queued at their services."""
        if self._graph_changed():
            self._directory.find_outside_clients(self._namespaces)
        self._directory.take_outside_requests()

    def close(self) -> None:
        if self._graph is not None:
            self._graph.close()
