"""CPU seconds spent inside the nodes' own code, in this process: what the host does not cost.

The host's callback guard adds the CPU time of guarded callbacks of a node (its thread's, so
that time waiting for a core is not counted), and the ``SwarmController`` base class adds only
its ``on_tick`` (its decoding and answering are the host's); both time a random sample of them.
The benchmark's host cost per robot-tick is the run's CPU time minus this.
"""
from __future__ import annotations

import random
import time

# A thread's CPU clock is a system call (0.4 µs alone, about 1.2 µs inside a busy run), two per
# timed callback: timing every one cost a few per cent of a flocking tick. One callback in
# SAMPLE_ONE_IN is timed, picked at random (no robot or node always or never), and counts for
# SAMPLE_ONE_IN: over a run's thousands of callbacks the sum is the same within a per cent.
SAMPLE_ONE_IN = 8
_P = 1.0 / SAMPLE_ONE_IN
_draw = random.Random().random     # its own generator: a node that seeds ``random`` gets its own draws

_seconds = 0.0


def sampled() -> bool:
    """Is this callback one to time (``started``, then ``add``)?"""
    return _draw() < _P


def started() -> float:
    return time.thread_time()


def add(started_at: float) -> None:
    """A sampled callback that began at ``started()`` ended."""
    global _seconds
    _seconds += (time.thread_time() - started_at) * SAMPLE_ONE_IN


def seconds() -> float:
    return _seconds
