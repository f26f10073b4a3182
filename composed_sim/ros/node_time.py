"""CPU seconds spent inside the nodes' own code, in this process: what the host does not cost.

The host's callback guard adds the CPU time of each guarded callback of a node (its thread's, so
that time waiting for a core is not counted), and the ``SwarmController`` base class adds only
its ``on_tick`` (its decoding and answering are the host's). The benchmark's host cost per
robot-tick is the run's CPU time minus this.

A thread's CPU clock is a system call (about 0.45 µs on the benchmark machine, twice per timed
callback: two of every tick's microseconds per robot), so one callback in ``SAMPLE_EVERY``, drawn
at random, is timed and counts ``SAMPLE_EVERY`` times: an estimate of the total from thousands of
samples per second of a run. The draws come from a generator of this module's own, so that the
nodes' use of ``random`` is untouched.
"""
from __future__ import annotations

import random
import time

SAMPLE_EVERY = 8

_seconds = 0.0
_draw = random.Random(0x5EED).random
_FRACTION = 1.0 / SAMPLE_EVERY


def start() -> float:
    """Before a callback: its thread's CPU time if this one is timed, else -1 (not timed)."""
    return time.thread_time() if _draw() < _FRACTION else -1.0


def stop(started: float) -> None:
    """After it: counts its CPU time, scaled, if ``start`` chose to time it."""
    global _seconds
    if started >= 0.0:
        _seconds += (time.thread_time() - started) * SAMPLE_EVERY


def seconds() -> float:
    return _seconds
