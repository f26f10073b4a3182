"""CPU seconds spent inside the nodes' own code, in one process: what the host does not cost.

The callback guard (callback_guard.py) adds the CPU time of each guarded callback of a node (its
thread's, so that time waiting for a core is not counted); a ``SwarmController`` (ros/controller.py)
adds only its ``on_tick`` (its decoding and answering are the host's). The benchmark's host cost
per robot-tick is the run's CPU time minus this. One counter per participant groups, handed to the
guard that adds to it and the exchange that reports it.
"""
from __future__ import annotations


class NodeTime:
    def __init__(self) -> None:
        self.seconds = 0.0

    def add(self, seconds: float) -> None:
        self.seconds += seconds
