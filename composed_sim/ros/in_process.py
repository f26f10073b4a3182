"""In-process delivery: a hosted publisher hands its message straight to the hosted subscriptions
of its topic while nothing outside them listens; DDS carries it as soon as anything else does.

Inside one participant, a message costs an rclpy ``publish`` (serialize, write into the DDS
history, deliver to each matched reader) and a ``take`` per subscription, all under the GIL: most
of the host's cost per robot-tick (docs/speed.md, "Host cost per robot-tick"). A robot's sensor
messages go from the simulator node to that robot's nodes, and its answers back, all in this
process; when the publisher's matched subscriptions are exactly the linked ones, an inbox per
subscription does the same job for a fraction of the cost.

What a user sees through ROS does not change:

- every publisher and subscription still exists on DDS; the graph, the matching and the matched
  counts are DDS's own;
- a ``publish`` asks DDS for the publisher's matched count: once it exceeds the linked
  subscriptions (a recorder, ``ros2 topic echo``, another hosted node that subscribed later), or
  falls short of them (a linked one no longer matches), the message goes through DDS as before,
  and the linked subscriptions take it from there. The count changes only with the ROS graph, so
  it is asked on every message only while the graph may have changed (``GraphWatch``, once per
  tick), and remembered otherwise: an outside listener hears every message from the tick after
  its match on;
- a subscription that DDS may also have messages for (from a publisher that is not linked, a
  stray ``cmd_vel`` of another process, or a linked one that went through DDS) takes from DDS
  too, after its inbox;
- a subscription is linked only when DDS would deliver every message to it and its callback needs
  nothing DDS adds: the publisher's type, a QoS that matches any volatile publisher of the topic
  (volatile, no deadline, lifespan or manual liveliness), a callback of the message alone, a node
  that the lockstep executor walks (which takes from the inbox as it takes from DDS, in the same
  order: runs are identical either way). Its inbox keeps the last ``depth`` messages (keep-last),
  as the subscription's DDS history does;
- a linked subscription gets the published bytes (``raw=True``) or a message object built from
  them: its own copy, as from DDS. Where the simulator's sensor messages reach subscriptions of
  the bytes, their readings go beside them, decoded for the whole group at once
  (devices/common/handoff.py).
"""
from __future__ import annotations

import os
import time
from collections import deque
from typing import Callable, Iterable, Optional, Sequence

from rclpy.publisher import Publisher
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                       ReliabilityPolicy)
from rclpy.serialization import serialize_message
from rclpy.subscription import Subscription

from composed_sim.ros import message_objects

# Set to 0 to send every hosted message through DDS (a comparison, or a suspected link).
SWITCH_ENV = "COMPOSED_SIM_IN_PROCESS"
_INBOX = "in_process_inbox"      # the attribute of a linked subscription that holds its Inbox
_DEFAULT_DURATION = QoSProfile(depth=1).deadline  # "not set": no deadline, lifespan, lease


class Inbox:
    """A linked subscription's queue of serialized messages, keep-last ``depth`` (0: keep all),
    and what tells whether DDS may hold messages for it too: a publisher that is not linked (one
    in another process, say) or a linked one that went through DDS (someone else listens)."""

    __slots__ = ("queue", "take", "raw", "links", "via_dds", "checking", "_foreign", "_matched")

    def __init__(self, depth: int, msg_type: Optional[type], matched_publishers: Callable[[], int], *,
                 timed: bool = False):
        """``matched_publishers``: the subscription's matched count (O(1), from DDS); ``timed``:
        its items are (bytes, publication time ns), ``take`` returns (message, time ns)."""
        self.queue: deque = deque(maxlen=depth or None)
        self.raw = msg_type is None    # its subscription gets the bytes
        popleft = self.queue.popleft
        # What the subscription's callback gets: the bytes (raw), or its own message object.
        convert = (lambda data: data) if msg_type is None else message_objects.builder(msg_type)
        if timed:
            def take_timed():
                data, published_ns = popleft()
                return convert(data), published_ns
            self.take: Callable[[], object] = take_timed
        else:
            self.take = popleft if msg_type is None else (lambda: convert(popleft()))
        self.links = 0                 # publishers linked to it
        self.via_dds = False           # a linked publisher sent through DDS since DDS was last empty
        self.checking = True           # ask DDS on every call (else: its last answer; ``GraphWatch``)
        self._foreign = True
        self._matched = matched_publishers

    def dds_may_hold(self) -> bool:
        """Must the subscription also take from DDS? Once a take finds nothing, ``emptied``."""
        if self.checking:
            self._foreign = self._matched() != self.links
        return self.via_dds or self._foreign

    def emptied(self) -> None:
        self.via_dds = False


def enabled() -> bool:
    return os.environ.get(SWITCH_ENV, "1") != "0"


def inbox_of(subscription) -> Optional[Inbox]:
    """The subscription's inbox, if it is linked (the lockstep executor's walk asks once)."""
    return getattr(subscription, _INBOX, None)


def _plain_qos(qos: QoSProfile) -> bool:
    """Matches every volatile publisher's offer (reliable or not), and adds nothing DDS would
    enforce on the way: no deadline, lifespan or manual liveliness."""
    return (qos.durability in (DurabilityPolicy.VOLATILE, DurabilityPolicy.SYSTEM_DEFAULT)
            and qos.liveliness in (LivelinessPolicy.AUTOMATIC, LivelinessPolicy.SYSTEM_DEFAULT)
            and qos.deadline == _DEFAULT_DURATION and qos.lifespan == _DEFAULT_DURATION)


def _depth(qos: QoSProfile) -> int:
    return 0 if qos.history == HistoryPolicy.KEEP_ALL else qos.depth


def linkable(subscription: Subscription, publisher: Publisher) -> bool:
    """Would DDS hand this subscription every message of ``publisher`` as the link does?"""
    return subscription._callback_type is Subscription.CallbackType.MessageOnly \
        and receives_all(subscription.msg_type, subscription.qos_profile, publisher)


def receives_all(msg_type: type, qos: QoSProfile, publisher: Publisher) -> bool:
    """Does a subscription of ``msg_type`` and ``qos`` get every message of ``publisher`` as
    the link hands it over, with nothing DDS would add (a transient-local publisher's history
    for a late outside subscriber, a deadline, a lifespan)?"""
    if msg_type is not publisher.msg_type:
        return False
    offered = publisher.qos_profile
    if offered.durability == DurabilityPolicy.TRANSIENT_LOCAL or not _plain_qos(offered):
        return False
    if offered.reliability == ReliabilityPolicy.BEST_EFFORT and qos.reliability != ReliabilityPolicy.BEST_EFFORT:
        return False
    return _plain_qos(qos)


class Link:
    """One publisher's in-process path to its topic's linked subscriptions: installed as the
    publisher's ``publish``, it checks the matched count (the rule above) on every message while
    ``checking``, and keeps its last answer otherwise."""

    def __init__(self, publisher: Publisher, inboxes: Sequence[Inbox],
                 wrap: Optional[Callable[[bytes], object]] = None):
        """``inboxes``: the linked subscriptions'; ``wrap``: what goes into them of the
        message's bytes (the answer subscription keeps the publisher's GID beside them; None:
        the bytes alone)."""
        self.publisher = publisher
        self.topic = publisher.topic_name
        self._through_dds = publisher.publish        # the original: rclpy's publish
        self.matched = self._matched = publisher.handle.get_subscription_count
        self._msg_type = publisher.msg_type
        self._inboxes = tuple(inboxes)
        self._queues = tuple(inbox.queue for inbox in self._inboxes)
        self._linked = len(self._inboxes)
        for inbox in self._inboxes:
            inbox.links += 1
        self._wrap = wrap
        self.in_process = 0                          # messages delivered in process (tests)
        self.checking = True                         # ask DDS on every message (else: its last answer)
        self._direct = False
        publisher.publish = self.publish

    @property
    def reaches_raw(self) -> bool:
        """Does a linked subscription get the bytes themselves (``raw=True``)?"""
        return any(inbox.raw for inbox in self._inboxes)

    def publish_check(self) -> None:
        """Ask DDS now whether the next messages may go in process."""
        self._direct = self._matched() == self._linked

    def publish(self, msg) -> None:
        if self.checking:
            self._direct = self._matched() == self._linked
        if not self._direct:
            for inbox in self._inboxes:
                inbox.via_dds = True
            self._through_dds(msg)
            return
        if msg.__class__ is not bytes:
            if not isinstance(msg, self._msg_type):
                self._through_dds(msg)               # rclpy's TypeError
                return
            msg = serialize_message(msg)
        item = msg if self._wrap is None else self._wrap(msg)
        for queue in self._queues:
            queue.append(item)
        self.in_process += 1


def link_subscriptions(publishers: Iterable[Publisher], subscriptions: Iterable[Subscription], *,
                       timed: bool = False) -> list[Link]:
    """Link each publisher to the subscriptions of its topic among ``subscriptions`` (nodes that a
    lockstep executor walks, or an inbox the simulator drains), where every one of them is
    linkable; the others stay on DDS. ``timed``: each message goes with the wall time it was
    published at (ns), as DDS's source timestamp (the simulator's drained inboxes tell late
    LEDs by it); the inbox's ``take`` then returns (message, time)."""
    by_topic: dict[str, list[Subscription]] = {}
    for sub in subscriptions:
        by_topic.setdefault(sub.topic_name, []).append(sub)
    links = []
    for publisher in publishers:
        subs = by_topic.get(publisher.topic_name)
        if not subs or not all(linkable(s, publisher) for s in subs):
            continue
        for sub in subs:
            if inbox_of(sub) is None:
                setattr(sub, _INBOX, Inbox(_depth(sub.qos_profile), None if sub.raw else sub.msg_type,
                                           sub.handle.get_publisher_count, timed=timed))
        links.append(Link(publisher, [inbox_of(s) for s in subs], (lambda data: (data, time.time_ns())) if timed
                          else None))
    return links


class GraphWatch:
    """When may a link's matched counts have changed? Only when this participant's ROS graph did:
    an endpoint of another process (or a new one of this process) was discovered or went away.
    Asking DDS for the counts on every message cost about a sixth of the host's time at 1280
    robots; the graph's guard condition (its changes counted by a thread, ros/rcl_graph.py),
    looked at once per tick, says when to ask. Discovery reports an endpoint to the graph and
    matches it a moment apart (measured: up to a third of a second), so after each change the
    links ask on every message for SETTLE_S, and then keep their last answer until the graph
    changes again."""

    SETTLE_S = 2.0

    def __init__(self, changed: Callable[[], bool], links: Sequence, inboxes: Sequence[Inbox]):
        """``changed``: has the participant's graph changed since the last call
        (``GraphChanges.poll``, ros/rcl_graph.py)? ``links``: what asks DDS for matched counts
        while ``checking`` and takes one last look (``publish_check``) before it keeps its
        answers: the ``Link``s, and the simulator's device publishers (devices/common/device.py),
        which ask whether a robot's topic is read."""
        self._changed = changed
        self._links, self._inboxes = list(links), list(inboxes)
        self._until = -1.0               # asking on every message until then (monotonic s)
        self._checking = True

    def start_tick(self, now: float) -> None:
        """Before a tick's messages: ask on every message while the graph may still settle."""
        if self._changed():
            self._until = now + self.SETTLE_S
        checking = now < self._until
        if checking != self._checking:
            self._checking = checking
            if not checking:             # one last look, then its answer holds
                for link in self._links:
                    link.publish_check()
                for inbox in self._inboxes:
                    inbox.checking = True
                    inbox.dds_may_hold()
            for item in (*self._links, *self._inboxes):
                item.checking = checking


def link_answers(publishers: Iterable[Publisher], answers, gid_of: Callable[[Publisher], bytes]) -> list[Link]:
    """Link a robot's cmd_vel ``publishers`` to the simulator node's answer subscription
    (ros/answer_subscription.py), which takes (bytes, publisher GID) from its inbox first."""
    return [Link(p, [answers.inbox], lambda data, gid=gid_of(p): (data, gid)) for p in publishers    # noqa: B008 - each publisher's GID, bound once
            if receives_all(answers.msg_type, answers.qos, p)]
