"""An rclpy executor made for lockstep ticks.

The stock executors rebuild a wait set over every entity of every node on each spin: with
thousands of hosted nodes that dominates the tick (docs/architecture.md has the figures). In a
lockstep tick the work is known: the simulator publishes every robot's sensors, and inside one
DDS participant a published message is ready to take at once. So this executor first walks the
subscriptions and timers of its nodes in a fixed order (nodes in the order they were added, each
node's subscriptions in creation order, then the waitables that can be taken without a wait set
(the simulator's cmd_vel subscriptions, ros/answer_subscription.py), then its timers), takes one
ready message from each sensor subscription (a robot's sensors come once per tick) and every ready
message from any other subscription (a robot's own topics between its nodes), fires each timer
that is due, and runs the callbacks; a callback's own publishes (a controller's answer, a message
to a later node of the robot) are picked up by the same walk. A controller whose host set its
``lockstep_batch`` (ros/controller.py) gets a tick's sensor messages in one call when all of them
wait in process. Only when a walk finds nothing does it fall
back to the ordinary wait set, which also serves services, guard conditions and messages from
other processes.

Callbacks run in the calling thread, in that fixed order: runs are deterministic and a plugin
needs no locks.
"""
from __future__ import annotations

from typing import Optional

from rclpy.event_handler import EventHandler
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.subscription import Subscription

from composed_sim.ros import contract as c
from composed_sim.ros.in_process import inbox_of

_SENSOR_NAMES = frozenset(t.name for t in c.SENSOR_TOPICS)


def _once_per_tick(topic: str) -> bool:
    """A robot's sensor topic (``/<robot>/<sensor>``): one message per tick."""
    parts = topic.split("/")
    return len(parts) == 3 and parts[2] in _SENSOR_NAMES


_WAITABLE = object()     # marks a waitable with dispatch_ready() in the walk's entity list
_BATCH = object()        # marks a node's sensor subscriptions handled in one call (``lockstep_batch``)


def _batch_entity(node: Node) -> list[tuple]:
    """The walk's entity for a node's ``lockstep_batch`` (ros/controller.py), set by its host:
    its subscriptions must be the node's first ones, all linked in process."""
    batch = getattr(node, "lockstep_batch", None)
    if not batch or not batch[0]:
        return []
    subscriptions, callback = batch
    inboxes = tuple(inbox_of(s) for s in subscriptions)
    if list(node.subscriptions)[:len(subscriptions)] != list(subscriptions) or None in inboxes:
        return []
    return [(callback, None, _BATCH, None, None, len(subscriptions), inboxes)]


class LockstepExecutor(SingleThreadedExecutor):
    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._ordered_nodes: list[Node] = []
        self._entities: Optional[list[tuple]] = None   # rebuilt when entities change
        self._covers_all: Optional[bool] = None

    def add_node(self, node: Node) -> bool:
        added = super().add_node(node)
        if added:
            self._ordered_nodes.append(node)
            self._entities = self._covers_all = None
        return added

    def remove_node(self, node: Node) -> None:
        super().remove_node(node)
        if node in self._ordered_nodes:
            self._ordered_nodes.remove(node)
        self._entities = self._covers_all = None

    def wake(self) -> None:
        # Nodes call this when they create or destroy an entity.
        self._entities = self._covers_all = None
        super().wake()

    def spin_once(self, timeout_sec: Optional[float] = None) -> None:
        if self.dispatch_ready() == 0:
            super().spin_once(timeout_sec)

    @property
    def walk_covers_all(self) -> bool:
        """Does the walk see every entity its nodes have (no services, clients, guard conditions
        or waitables it cannot take)? Then a walk that runs nothing means that nothing is ready.
        (A QoS event handler, which rclpy gives most endpoints, only reports a mismatch: it can
        wait for the next pass over the wait set.) Known afresh whenever the entities change."""
        if self._covers_all is None:
            self._covers_all = all(not any(True for _ in node.services) and not any(True for _ in node.clients)
                                   and not any(True for _ in node.guards)
                                   and all(hasattr(w, "dispatch_ready") or isinstance(w, EventHandler)
                                           for w in node.waitables)
                                   for node in self._ordered_nodes)
        return self._covers_all

    def dispatch_ready(self) -> int:
        """Take and handle every message ready now, and fire every timer due now, in the fixed
        order; returns how many callbacks ran."""
        entities = self._entities
        if entities is None:
            # What a walk needs of each entity, resolved once (properties cost a call each): per
            # node its subscriptions, then its timers. A timer on sim time is due only after its
            # robot's sensor callbacks of the tick (hosting/sim_timers.py), which the walk has just run:
            # its answer is then taken by the simulator node later in the same walk, as an answer
            # published from a sensor callback is.
            message_only = Subscription.CallbackType.MessageOnly
            # A subscription linked in process (ros/in_process.py) takes from its inbox first.
            entities = self._entities = [
                entity for node in self._ordered_nodes
                for entity in _batch_entity(node)
                + [(s, s.handle, s.msg_type, s.raw, s._callback_type is message_only,
                    _once_per_tick(s.topic_name), inbox_of(s)) for s in node.subscriptions]
                + [(w, None, _WAITABLE, None, None, True, None) for w in node.waitables if hasattr(w, "dispatch_ready")]
                + [(t, t.handle, None, None, None, True, None) for t in node.timers]]
        handled = skip = 0
        for entity, handle, msg_type, raw, message_only, once, inbox in entities:
            if skip:                               # a batch's subscriptions, handled by it this walk
                skip -= 1
                continue
            if msg_type is _BATCH:
                # A controller's sensor messages of the tick, all waiting in process and none in
                # DDS: one call with all of them, instead of one per subscription (the entities
                # that follow, which handle them one by one otherwise). ``once``: how many.
                for box in inbox:
                    if not box.queue or box.dds_may_hold():
                        break
                else:
                    entity([box.take() for box in inbox])
                    handled += once
                    skip = once
                continue
            if msg_type is _WAITABLE:
                handled += entity.dispatch_ready()
                continue
            if msg_type is None:                   # a timer
                with handle:
                    if not handle.is_timer_ready():
                        continue
                    handle.call_timer()
                entity.callback()
                handled += 1
                continue
            # One message per sensor subscription and walk: in a lockstep tick there is one, and
            # looking for a second would cost an empty take per subscription (any more are taken
            # by the next walk, in the same order). Every message queued on any other.
            if inbox is not None:                     # linked: its callback takes the message alone
                if inbox.queue:
                    entity.callback(inbox.take())
                    handled += 1
                    while not once and inbox.queue:
                        entity.callback(inbox.take())
                        handled += 1
                # DDS is asked only when it may hold a message too (an empty take costs a call
                # into rcl per subscription and walk).
                if not inbox.dds_may_hold():
                    continue
            while True:
                with handle:
                    taken = handle.take_message(msg_type, raw)
                if taken is None:
                    if inbox is not None:
                        inbox.emptied()
                    break
                if message_only:
                    entity.callback(taken[0])
                else:
                    entity.callback(*taken)
                handled += 1
                if once:
                    break
        return handled
