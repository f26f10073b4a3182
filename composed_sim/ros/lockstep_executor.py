"""An rclpy executor made for lockstep ticks.

The stock executors rebuild a wait set over every entity of every node on each spin: with
thousands of hosted nodes that dominates the tick (docs/architecture.md: 360–770 µs per robot-tick). In a
lockstep tick the work is known: the simulator publishes every robot's sensors, and inside one
DDS participant a published message is ready to take at once. So this executor first walks the
subscriptions of its nodes in a fixed order (nodes in the order they were added, subscriptions
in creation order), takes one ready message from each and runs the callbacks; a callback's own
publishes (a controller's answer) are picked up by the same walk. When a walk finds nothing, the
timers that are due fire, in the same order (a timer-driven controller answers from one); only when
there are none either does it fall back to the ordinary wait set, which also serves services, guard
conditions and messages from other processes.

Callbacks run in the calling thread, in that fixed order: runs are deterministic and a plugin
needs no locks.
"""
from __future__ import annotations

from typing import Optional

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.subscription import Subscription


class LockstepExecutor(SingleThreadedExecutor):
    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._ordered_nodes: list[Node] = []
        self._subscriptions: Optional[list[tuple]] = None   # rebuilt when entities change
        self._timers: Optional[list[tuple]] = None

    def add_node(self, node: Node) -> bool:
        added = super().add_node(node)
        if added:
            self._ordered_nodes.append(node)
            self._subscriptions = self._timers = None
        return added

    def remove_node(self, node: Node) -> None:
        super().remove_node(node)
        if node in self._ordered_nodes:
            self._ordered_nodes.remove(node)
        self._subscriptions = self._timers = None

    def wake(self) -> None:
        # Nodes call this when they create or destroy an entity.
        self._subscriptions = self._timers = None
        super().wake()

    def spin_once(self, timeout_sec: Optional[float] = None) -> None:
        if self.dispatch_ready() == 0:
            super().spin_once(timeout_sec)

    def dispatch_ready(self) -> int:
        """Take and handle every message ready now, in the fixed order; returns how many."""
        subs = self._subscriptions
        if subs is None:
            # What a walk needs of each subscription, resolved once (properties cost a call each).
            message_only = Subscription.CallbackType.MessageOnly
            subs = self._subscriptions = [(s, s.handle, s.msg_type, s.raw, s._callback_type is message_only)
                                          for node in self._ordered_nodes for s in node.subscriptions]
        handled = 0
        for sub, handle, msg_type, raw, message_only in subs:
            # One message per subscription and walk: in a lockstep tick there is one, and
            # looking for a second would cost an empty take per subscription. Any more are taken
            # by the next walk, in the same order.
            with handle:
                taken = handle.take_message(msg_type, raw)
            if taken is None:
                continue
            if message_only:
                sub.callback(taken[0])
            else:
                sub.callback(*taken)
            handled += 1
        if handled == 0:
            handled = self._fire_due_timers()
        return handled

    def _fire_due_timers(self) -> int:
        """Once the sensor callbacks are done (a walk found nothing): the timers due now, in the
        same fixed order. Timers on sim time become due only after their robot's sensor callbacks
        of the tick (ros/sim_timers.py), so this never runs one ahead of its readings."""
        timers = self._timers
        if timers is None:
            timers = self._timers = [(t, t.handle) for node in self._ordered_nodes for t in node.timers]
        fired = 0
        for timer, handle in timers:
            with handle:
                if not handle.is_timer_ready():
                    continue
                handle.call_timer()
            timer.callback()
            fired += 1
        return fired
