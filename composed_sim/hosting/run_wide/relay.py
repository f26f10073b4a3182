"""Run-wide topics: the topics outside every robot's namespace, delivered by the host.

A robot's own topics (``/bot3/scan``, ``/bot3/drive_command``) stay inside its participant and
go through DDS. A topic outside every robot's namespace (``/swarm_command``, ``/opinions``) is
one topic for the whole run, but the run's participants, worker processes and (multi-process)
domains do not hear one another, and a stock executor takes whatever happens to be ready when a
tick closes. So a hosted node's publisher on such a topic writes to the host's relay, and its
subscription is served by the relay, at one point of the tick and in one order in every executor,
host mode and worker layout (docs/contract.md, "Run-wide topics"):

- what robots publish while they answer tick k, and what run-wide nodes publish at the start of
  tick k+1, is delivered after tick k closes and before tick k+1's sensors are published:
  first the run-wide nodes' messages (in node order), then the robots' (in robot order), each
  publisher's in the order it published them;
- every subscriber gets every message of the batch, each its own copy, subscribers in the
  order the host built them (run-wide nodes first, then robot by robot).

The relay of each process keeps that process's subscribers and collects its publishers'
messages; the host moves the batches between processes (worker processes: with each tick's frame
and answers; controller processes: over DDS, hosting/run_wide/link.py). Messages travel as their CDR
bytes.
"""
from __future__ import annotations

import functools
import inspect
import threading
from typing import Callable, Collection, Optional

from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import Subscription

from composed_sim.ros import contract as c

# Topics every node has, or the contract's own run-wide topics: never relayed.
_NOT_RELAYED = frozenset({"/rosout", "/parameter_events", c.CLOCK_TOPIC, "/tf", "/tf_static",
                          c.SWARM_STATE_TOPIC, c.SWARM_MARKERS_TOPIC})

# One relayed message: (topic, type name, CDR bytes).
Message = tuple[str, str, bytes]


def is_run_wide(topic: str, robots: Collection[str]) -> bool:
    """Is the resolved ``topic`` outside every robot's namespace, and not one every node has?"""
    if topic in _NOT_RELAYED or topic.startswith("/_"):
        return False
    return c.namespace_head(topic) not in robots


class RelayPublisher:
    """What a hosted node's ``create_publisher`` returns for a run-wide topic: ``publish`` hands
    the message to the relay (it reaches every subscriber of the run at the tick's delivery)."""

    def __init__(self, relay: "RunWideRelay", origin: int, topic: str, msg_type: type):
        self._relay, self._origin = relay, origin
        self.topic_name, self.msg_type = topic, msg_type
        self._type_name = c.type_name(msg_type)

    @property
    def topic(self) -> str:
        return self.topic_name

    def publish(self, msg) -> None:
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        self._relay.post(self._origin, (self.topic_name, self._type_name, data))

    def get_subscription_count(self) -> int:
        return self._relay.subscriber_count(self.topic_name)

    def wait_for_all_acked(self, timeout=None) -> bool:
        return True

    def destroy(self) -> None:
        pass


class RelaySubscription:
    """What a hosted node's ``create_subscription`` returns for a run-wide topic: the relay calls
    its callback with each delivered message (or its bytes, for ``raw=True``)."""

    def __init__(self, relay: "RunWideRelay", topic: str, msg_type: type, callback: Callable, raw: bool,
                 callback_group):
        self._relay = relay
        self.topic_name, self.msg_type, self.raw = topic, msg_type, raw
        self.callback_group = callback_group
        self.type_name = c.type_name(msg_type)
        self.callback = callback
        # As rclpy decides it: a callback of two parameters also gets the message info.
        with_info = len(inspect.signature(callback).parameters) == 2
        self._callback_type = Subscription.CallbackType.WithMessageInfo if with_info \
            else Subscription.CallbackType.MessageOnly

    @property
    def topic(self) -> str:
        return self.topic_name

    def get_publisher_count(self) -> int:
        return 1

    def deliver(self, data: bytes):
        """The subscription's callback on the message; what it returns (an ``async def``'s
        coroutine, for the executor to run)."""
        msg = data if self.raw else deserialize_message(data, self.msg_type)
        if self._callback_type is Subscription.CallbackType.WithMessageInfo:
            return self.callback(msg, {})
        return self.callback(msg)

    def destroy(self) -> None:
        self._relay.remove(self)


class RunWideRelay:
    """One process's side of the run-wide topics: its nodes' subscriptions and published messages."""

    def __init__(self, robots: Collection[str]):
        self._robots = frozenset(robots)
        self._outbox: list[tuple[int, int, Message]] = []     # (origin, sequence, message)
        self._subscriptions: dict[str, list[RelaySubscription]] = {}
        self._by_node: dict[int, list[RelaySubscription]] = {}
        self._published_by: dict[int, set[str]] = {}
        self._lock = threading.Lock()     # callbacks may publish from several executor threads
        self._sequence = 0
        self._publishers = 0

    @property
    def in_use(self) -> bool:
        """Does any node of this process publish or subscribe on a run-wide topic?"""
        return bool(self._subscriptions) or self._publishers > 0

    def adopt(self, node: Node, origin: int) -> None:
        """Before ``node``'s constructor: its publishers and subscriptions on run-wide topics go
        through this relay. ``origin``: its robot's index in the run, or RUN_WIDE_ORIGIN."""
        create_publisher, create_subscription = node.create_publisher, node.create_subscription
        subscriptions = self._by_node.setdefault(id(node), [])

        def publisher(msg_type, topic, *args, **kwargs):
            name = node.resolve_topic_name(topic)
            if not is_run_wide(name, self._robots):
                return create_publisher(msg_type, topic, *args, **kwargs)
            self._publishers += 1
            self._published_by.setdefault(id(node), set()).add(name)
            return RelayPublisher(self, origin, name, msg_type)

        def subscription(msg_type, topic, callback, *args, raw: bool = False, callback_group=None, **kwargs):
            name = node.resolve_topic_name(topic)
            if not is_run_wide(name, self._robots):
                return create_subscription(msg_type, topic, callback, *args, raw=raw, callback_group=callback_group,
                                           **kwargs)
            sub = RelaySubscription(self, name, msg_type, callback, raw,
                                    callback_group or node.default_callback_group)
            with self._lock:
                self._subscriptions.setdefault(name, []).append(sub)
            subscriptions.append(sub)
            return sub
        node.create_publisher, node.create_subscription = publisher, subscription

    def subscriptions_of(self, node: Node) -> list[RelaySubscription]:
        return self._by_node.get(id(node), [])

    def topics_published_by(self, node: Node) -> set[str]:
        return self._published_by.get(id(node), set())

    def subscriber_count(self, topic: str) -> int:
        return len(self._subscriptions.get(topic, ()))

    def remove(self, sub: RelaySubscription) -> None:
        with self._lock:
            subs = self._subscriptions.get(sub.topic_name, [])
            if sub in subs:
                subs.remove(sub)

    # --- per tick ----------------------------------------------------------------------------

    def post(self, origin: int, message: Message) -> None:
        with self._lock:
            self._outbox.append((origin, self._sequence, message))
            self._sequence += 1

    def take_outbox(self) -> list[Message]:
        """The messages published since the last take: by origin (run-wide nodes first, then
        robot by robot), each origin's in the order published."""
        with self._lock:
            taken, self._outbox = self._outbox, []
        return [message for _, _, message in sorted(taken, key=lambda m: (m[0], m[1]))]

    def deliver(self, batch: list[Message], run: Optional[Callable[[Callable, object], None]] = None) -> None:
        """Every message of ``batch``, in order, to every subscriber of its topic in this process:
        now, or handed to ``run`` with the subscription's callback group (the lockstep executor's
        ``run_callback``: a task, in which a callback may wait or be a coroutine)."""
        for topic, type_name, data in batch:
            for sub in list(self._subscriptions.get(topic, ())):
                if sub.type_name == type_name:     # DDS would not match another type either
                    if run is None:
                        sub.deliver(data)
                    else:
                        run(functools.partial(sub.deliver, data), sub.callback_group)
