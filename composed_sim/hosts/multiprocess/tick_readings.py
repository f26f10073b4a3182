"""Which of a tick's sensor readings a controller process has taken (multi-process mode).

A robot whose nodes answer when they publish (``answers: when_published``, a drone, whose
firmware answers) sends its part of a tick once its nodes are idle: the simulator then takes that
robot as done with the tick. Each sensor reaches the process over DDS on its own, so the nodes may
be idle between two of a tick's readings: a part sent then would leave out what the later reading
leads to (a drone's setpoint, published from its pose callback after its rab_rx one), which then
counts for the tick after, sometimes. So the part waits until every sensor subscription that the
simulator publishes to has taken the tick's reading (``all_in``).

The walk of the lockstep executor takes them in one order, too: a node that reads two sensors
(a drone's rab_rx for its neighbours, its pose for its setpoint) handles them in subscription order
in one process; here DDS may deliver the later one first. So before a walk, while some of the
tick's readings are waiting and others not yet, it waits for the rest (``wait_for_the_rest``).
Either wait lasts at most ``patience_s`` (a reading lost).
"""
from __future__ import annotations

import time

from composed_sim.hosting import readings_waiting


class TickReadings:
    def __init__(self, context, patience_s: float):
        self._context, self._patience_s = context, patience_s
        self._last: dict[int, int] = {}            # id(subscription) → stamp of its last reading taken
        self._subscriptions: list = []
        self._served_at: tuple[int, list] = (-2, [])  # (newest stamp when looked up, the served ones)
        self._newest = -1                           # the newest reading's stamp (ns): the tick's
        self._since: tuple[int, float] = (-1, 0.0)  # (stamp, when ``all_in`` first waited for it)

    def watch(self, subscriptions) -> None:
        """More of the robot's sensor subscriptions (one made in a transition, say)."""
        self._subscriptions += subscriptions
        self._served_at = (-2, [])

    def taken(self, stamp: int, subscription) -> None:
        """``subscription``'s callback of the tick at ``stamp`` (ns) begins."""
        self._last[id(subscription)] = stamp
        self._newest = max(self._newest, stamp)

    def _served(self) -> list:
        # Only the subscriptions a publisher serves get a reading each tick (looked up once a tick:
        # each look asks the ROS graph).
        if self._served_at[0] != self._newest or self._newest < 0:      # before tick 0: still matching
            self._served_at = (self._newest, [s for s in self._subscriptions if s.get_publisher_count() > 0])
        return self._served_at[1]

    def all_in(self, stamp: int) -> bool:
        """Has every reading of the tick at ``stamp`` been taken (or waited for long enough)?"""
        if all(self._last.get(id(s), -1) >= stamp for s in self._served()):
            return True
        if self._since[0] != stamp:
            self._since = (stamp, time.monotonic())
        return time.monotonic() - self._since[1] > self._patience_s

    def wait_for_the_rest(self) -> None:
        """While some of the next readings wait to be taken and others have not come yet, wait for
        those. The next readings: of the subscriptions that have not taken the newest tick's, or, once
        all have, of every one (the next tick's)."""
        served = self._served()
        pending = [s for s in served if self._last.get(id(s), -1) < self._newest] or served
        if len(pending) < 2:
            return
        waiting = readings_waiting(pending, self._context)
        deadline = time.monotonic() + self._patience_s
        while any(waiting) and not all(waiting) and (left := deadline - time.monotonic()) > 0:
            # Asleep until one of those not come yet comes (a wait set of them alone).
            late = [s for s, w in zip(pending, waiting) if not w]
            if any(readings_waiting(late, self._context, left)):
                waiting = readings_waiting(pending, self._context)
