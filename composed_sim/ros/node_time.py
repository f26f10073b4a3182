"""CPU seconds spent inside the nodes' own code, in this process: what the host does not cost.

The host's callback guard adds the CPU time of each guarded callback of a node (its thread's, so
that time waiting for a core is not counted), and the ``SwarmController`` base class adds only
its ``on_tick`` (its decoding and answering are the host's). The benchmark's host cost per
robot-tick is the run's CPU time minus this.
"""
from __future__ import annotations

_seconds = 0.0


def add(seconds: float) -> None:
    global _seconds
    _seconds += seconds


def seconds() -> float:
    return _seconds
