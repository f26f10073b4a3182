"""What the lockstep executor's walk needs of each entity of its nodes, resolved once whenever the
entities change (a property costs a call each time it is read, and the walk reads them every tick).

The walk goes over the entries in one order: nodes in the order they were added; per node its
sensor batch (``lockstep_batch``, ros/controller.py), its subscriptions, the waitables it can take
without a wait set, its services served in process, its action endpoints and clients with
responses through DDS, then its timers. A timer on sim time is due only after its robot's sensor
callbacks of the tick (hosting/sim_time/timers.py), which the walk has just run: its answer is then
taken by the simulator node later in the same walk.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.subscription import Subscription

from composed_sim.ros import contract as c
from composed_sim.ros.in_process import inbox_of

# What an entry is (its ``kind``; a subscription's is its message type).
WAITABLE = object()     # a waitable with dispatch_ready() (the simulator's answer subscriptions)
BATCH = object()        # a node's sensor subscriptions handled in one call (``lockstep_batch``)
SERVICE = object()      # a node's services served in process (hosting/calls/served.py)
POLLED = object()       # polled by the service directory: action endpoints, clients' DDS responses
TIMER = None
OWN_GROUP = object()    # a timer or subscription whose callback group is the node's own kind (below)

_SENSOR_NAMES = frozenset(t.name for t in c.SENSOR_TOPICS)


class WalkEntry(NamedTuple):
    """One entry of the walk; a tuple, unpacked in the walk's loop at a tuple's speed."""
    entity: object                  # the subscription, timer, waitable, NodeServices, or a batch's callback
    handle: object = None           # its rcl handle (subscriptions, timers)
    kind: object = TIMER            # a subscription's message type, or one of the kinds above
    raw: Optional[bool] = None      # a subscription that takes serialized messages
    message_only: Optional[bool] = None   # a subscription callback that takes the message alone
    once: object = None             # one message per walk (a robot's sensor topic); a batch's size
    inbox: object = None            # its in-process inbox (ros/in_process.py); a batch's inboxes
    group: object = None            # its callback group
    node: Optional[Node] = None


def once_per_tick(topic: str) -> bool:
    """A robot's sensor topic (``/<robot>/<sensor>``): one message per tick."""
    parts = topic.split("/")
    return len(parts) == 3 and parts[2] in _SENSOR_NAMES


def batch_entry(node: Node) -> list[WalkEntry]:
    """The walk's entry for a node's ``lockstep_batch`` (ros/controller.py), set by its host:
    its subscriptions must be the node's first ones, all linked in process."""
    batch = getattr(node, "lockstep_batch", None)
    if not batch or not batch[0]:
        return []
    subscriptions, callback = batch
    inboxes = tuple(inbox_of(s) for s in subscriptions)
    if list(node.subscriptions)[:len(subscriptions)] != list(subscriptions) or None in inboxes:
        return []
    return [WalkEntry(callback, kind=BATCH, once=len(subscriptions), inbox=inboxes,
                      group=subscriptions[0].callback_group, node=node)]


def walk_entries(nodes: list[Node], services) -> list[WalkEntry]:
    """The entries of ``nodes``, in the walk's order; ``services``: the executor's ServiceDirectory
    (hosting/calls/directory.py), None where its nodes are not hosted."""
    message_only = Subscription.CallbackType.MessageOnly
    entries: list[WalkEntry] = []
    for node in nodes:
        entries += batch_entry(node)
        # A subscription linked in process (ros/in_process.py) takes from its inbox first.
        entries += [in_own_group(WalkEntry(s, s.handle, s.msg_type, s.raw, s._callback_type is message_only,
                                           once_per_tick(s.topic_name), inbox_of(s), s.callback_group, node))
                    for s in node.subscriptions]
        entries += [WalkEntry(w, kind=WAITABLE, once=True, node=node)
                    for w in node.waitables if hasattr(w, "dispatch_ready")]
        if services is not None:
            served = services.services_of(node)
            entries += [WalkEntry(served, kind=SERVICE, node=node)] if served is not None else []
            entries += [WalkEntry(w, kind=POLLED, group=w.callback_group, node=node)
                        for w in node.waitables if services.polls(w)]
            entries += [WalkEntry(cl, kind=POLLED, node=node)
                        for cl in node.clients if services.takes_responses(cl)]
        entries += [in_own_group(WalkEntry(t, t.handle, TIMER, once=True, group=t.callback_group, node=node))
                    for t in node.timers]
    return entries


def in_own_group(entry: WalkEntry) -> WalkEntry:
    """A timer's or subscription's entry; wrapped in an ``OWN_GROUP`` entry where its callback group is
    a kind of the node's own (a subclass of rclpy's ``CallbackGroup`` that decides itself, in
    ``can_execute`` and ``beginning_execution``, when its callbacks may run: a throttle, say), which
    the walk asks as rclpy's executors do. rclpy's two kinds cost the walk nothing more."""
    if entry.group is None or type(entry.group) in (MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup):
        return entry
    return WalkEntry(entry, kind=OWN_GROUP, group=entry.group, node=entry.node)
