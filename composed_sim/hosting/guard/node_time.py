"""CPU seconds spent inside the nodes' own code, in one process: what the host does not cost.

The callback guard (callback_guard.py) times each guarded callback of a node (its thread's CPU
clock, so that time waiting for a core is not counted); a ``SwarmController`` (ros/controller.py)
times only its ``on_tick`` (its decoding and answering are the host's). The benchmark's host cost
per robot-tick is the run's CPU time minus this. One counter per participant groups, handed to the
guard that adds to it and the exchange that reports it.

The first ``TIMED_FIRST`` calls are each timed; after them a call is timed one time in
``SAMPLED``, drawn at random, and counts ``SAMPLED`` times (the sum's expected value is the same): the
thread's CPU clock is a system call (about 0.6 µs here, more in place), and reading it twice per
robot-tick cost 3–4 µs of the host's at 1280 flocking robots. The draw is a seeded generator's,
apart from the run's randomness; it never touches a trajectory.
"""
from __future__ import annotations

import random
import time
from typing import Optional

TIMED_FIRST = 1024
SAMPLED = 32


class NodeTime:
    def __init__(self) -> None:
        self.seconds = 0.0
        self._first = TIMED_FIRST
        self._draw = random.Random(0).random

    def start(self) -> Optional[tuple[float, int]]:
        """At a call's start: where this call is timed, the thread's CPU clock and what the call
        counts for; else None."""
        if self._first:
            self._first -= 1
            return time.thread_time(), 1
        return (time.thread_time(), SAMPLED) if self._draw() * SAMPLED < 1.0 else None

    def stop(self, started: Optional[tuple[float, int]]) -> None:
        """At its end (``started``: what ``start`` gave)."""
        if started is not None:
            self.seconds += (time.thread_time() - started[0]) * started[1]
