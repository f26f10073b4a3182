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
messages; the host moves the batches between processes. Messages travel as their CDR bytes.
"""
from __future__ import annotations

import inspect
import pickle
import threading
import time
from array import array
from typing import Callable, Collection

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import Subscription
from std_msgs.msg import UInt8MultiArray

from composed_sim.ros import contract as c
from composed_sim.ros.robot_settings import quiet_node_options

# Topics every node has, or the contract's own run-wide topics: never relayed.
_NOT_RELAYED = frozenset({"/rosout", "/parameter_events", c.CLOCK_TOPIC, "/tf", "/tf_static",
                          c.SWARM_STATE_TOPIC, c.SWARM_MARKERS_TOPIC})
RUN_WIDE_ORIGIN = -1        # the origin of a run-wide node's messages: before every robot's

# One relayed message: (topic, type name, CDR bytes).
Message = tuple[str, str, bytes]


def is_run_wide(topic: str, robots: Collection[str]) -> bool:
    """Is the resolved ``topic`` outside every robot's namespace, and not one every node has?"""
    if topic in _NOT_RELAYED or topic.startswith("/_"):
        return False
    first = topic.split("/", 2)[1]
    return first not in robots


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

    def __init__(self, relay: "RunWideRelay", topic: str, msg_type: type, callback: Callable, raw: bool):
        self._relay = relay
        self.topic_name, self.msg_type, self.raw = topic, msg_type, raw
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

    def deliver(self, data: bytes) -> None:
        msg = data if self.raw else deserialize_message(data, self.msg_type)
        if self._callback_type is Subscription.CallbackType.WithMessageInfo:
            self.callback(msg, {})
        else:
            self.callback(msg)

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

        def subscription(msg_type, topic, callback, *args, raw: bool = False, **kwargs):
            name = node.resolve_topic_name(topic)
            if not is_run_wide(name, self._robots):
                return create_subscription(msg_type, topic, callback, *args, raw=raw, **kwargs)
            sub = RelaySubscription(self, name, msg_type, callback, raw)
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

    def deliver(self, batch: list[Message]) -> None:
        """Every message of ``batch``, in order, to every subscriber of its topic in this process."""
        for topic, type_name, data in batch:
            for sub in list(self._subscriptions.get(topic, ())):
                if sub.type_name == type_name:     # DDS would not match another type either
                    sub.deliver(data)


# --- across processes (multi-process mode) --------------------------------------------------------
#
# A controller process has a relay of its own. Its robot's messages of tick k go to the simulator
# on /<robot>/_composed_sim/run_wide, once the robot's nodes have nothing left to do in the tick;
# the simulator publishes each tick's batch on /_composed_sim/run_wide in every domain before the
# tick's sensors, and a controller process delivers it before the first sensor callback of the
# tick runs. Both carry (stamp ns, messages), pickled, in a std_msgs/UInt8MultiArray.

BATCH_TOPIC = "/_composed_sim/run_wide"
LINK_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)


def outbox_topic(robot: str) -> str:
    return f"/{robot}/_composed_sim/run_wide"


def pack(stamp_ns: int, messages: list[Message], answered: bool = False, logs: tuple = ()) -> UInt8MultiArray:
    """``answered``: a robot's part says whether its nodes published cmd_vel in the tick; ``logs``:
    what its log lines give the simulator's console and /rosout (``NodeLogs.drain``)."""
    return UInt8MultiArray(data=array("B", pickle.dumps((stamp_ns, messages, answered, logs),
                                                        protocol=pickle.HIGHEST_PROTOCOL)))


def unpack(msg: UInt8MultiArray) -> tuple[int, list[Message], bool, tuple]:
    return pickle.loads(bytes(msg.data))


class RunWideLink:
    """A controller process's side of the run: it takes each tick's batch from the simulator
    before the robot's first sensor callback of the tick (``before_tick``) and sends what the
    robot's nodes published once they are idle (``send``): every tick if ``sends`` (the simulator
    waits for it), else only when its log lines have something for the simulator's console or
    /rosout (``logs``, a forwarding ``NodeLogs``)."""

    def __init__(self, context, robot: str, relay: RunWideRelay, *, receives: bool, sends: bool,
                 timeout_s: float, logs=None):
        self._relay, self._timeout_s, self._logs = relay, timeout_s, logs
        self.sends = sends
        self.node = Node("run_wide_link", namespace=f"/{robot}", context=context, **quiet_node_options())
        self._batches = self.node.create_subscription(UInt8MultiArray, BATCH_TOPIC, lambda msg: None, LINK_QOS) \
            if receives else None
        self._outbox = self.node.create_publisher(UInt8MultiArray, outbox_topic(robot), LINK_QOS) \
            if sends or logs is not None else None
        self.delivered = -1         # stamp of the last batch delivered
        self.tick = -1              # stamp of the last tick whose sensors arrived
        self.sent = -1              # stamp of the last tick whose messages went out
        self.answered = -1          # stamp of the last tick the robot's nodes published cmd_vel in

    @property
    def endpoints(self) -> list:
        return [e for e in (self._batches, self._outbox) if e is not None]

    def before_tick(self, stamp: int) -> None:
        """Before the robot's first sensor callback of a tick (``sim_timers.before_each_tick``):
        the tick's batch is delivered, waiting for it."""
        self.tick = max(self.tick, stamp)
        if self._batches is not None:
            self._deliver_through(stamp)

    def watch_answers(self, publishers) -> None:
        """Note the ticks in which the robot's cmd_vel ``publishers`` publish (the simulator then
        waits for the answer itself, not only for the sign that the robot is idle)."""
        for publisher in publishers:
            publish = publisher.publish

            def noting(msg, publish=publish):
                self.answered = self.tick
                return publish(msg)
            publisher.publish = noting

    def _deliver_through(self, stamp: int) -> None:
        deadline = time.monotonic() + self._timeout_s
        while self.delivered < stamp:
            with self._batches.handle:
                taken = self._batches.handle.take_message(UInt8MultiArray, False)
            if taken is None:
                if time.monotonic() > deadline:
                    return          # the simulator is gone or stopped: the tick goes on without
                time.sleep(0.0002)
                continue
            batch_stamp, batch, _, _ = unpack(taken[0])
            self._relay.deliver(batch)
            self.delivered = batch_stamp

    def send(self) -> None:
        """What the robot's nodes published in the tick of the last sensors, to the simulator."""
        logs = self._logs.drain() if self._logs is not None else ()
        self._outbox.publish(pack(self.tick, self._relay.take_outbox(), self.answered == self.tick, logs))
        self.sent = self.tick

    def send_logs(self) -> None:
        """A robot whose part the simulator does not wait for: its log lines' part, if any."""
        if self._logs is not None and self._logs.forwarding:
            self._outbox.publish(pack(self.tick, [], False, self._logs.drain()))

    def destroy(self) -> None:
        self.node.destroy_node()


class SimulatorLink:
    """The simulator's side of the run-wide relay in one ROS domain (multi-process mode): it
    publishes each tick's batch there and takes what each robot of the domain sent."""

    def __init__(self, context, name: str, logs=None):
        """``logs``: the simulator's ``NodeLogs``, into which the robots' log lines' parts go."""
        self.node = Node(name, context=context, **quiet_node_options())
        self._logs = logs
        self._log_senders: dict[int, object] = {}     # robots whose parts carry only their logs
        self._batches = self.node.create_publisher(UInt8MultiArray, BATCH_TOPIC, LINK_QOS)
        self._receivers = 0
        self._outboxes: dict[int, object] = {}       # robot index in the run → its subscription
        self._pending: dict[int, list[Message]] = {}  # what a robot sent for the open tick so far
        self._done: set[int] = set()                  # robots whose messages of the open tick are in
        self.answered: set[int] = set()               # … of which those that published cmd_vel in it

    def add_robot(self, index: int, robot: str, topics: Collection[str], waited: bool = True) -> dict[str, object]:
        """A controller process reported its link's topics: its endpoints on this side, by topic
        (each answers ``get_*_count() >= 1`` once matched, as the start-up check asks). ``waited``:
        its part comes every tick and closes it; else it carries only log lines, now and then."""
        endpoints = {}
        if BATCH_TOPIC in topics:
            self._receivers += 1
            endpoints[BATCH_TOPIC] = _AllReceivers(self._batches, self._receivers)
        if outbox_topic(robot) in topics:
            sub = self.node.create_subscription(UInt8MultiArray, outbox_topic(robot), lambda msg: None, LINK_QOS)
            (self._outboxes if waited else self._log_senders)[index] = sub
            endpoints[outbox_topic(robot)] = sub
        return endpoints

    @property
    def senders(self) -> list[int]:
        return list(self._outboxes)

    def publish(self, stamp_ns: int, batch: list[Message]) -> None:
        if self._receivers:
            self._batches.publish(pack(stamp_ns, batch))

    def take(self, stamp_ns: int, waiting: Collection[int]) -> None:
        """Take what arrived from the robots ``waiting`` (indices) for ticks up to ``stamp_ns``."""
        for index in waiting:
            sub = self._outboxes[index]
            while index not in self._done:
                with sub.handle:
                    taken = sub.handle.take_message(UInt8MultiArray, False)
                if taken is None:
                    break
                stamp, messages, answered, logs = unpack(taken[0])
                self._merge_logs(logs)
                self._pending.setdefault(index, []).extend(messages)
                if stamp >= stamp_ns:
                    self._done.add(index)
                    if answered:
                        self.answered.add(index)

    def take_logs(self) -> None:
        """What the robots that send only their log lines sent so far."""
        for sub in self._log_senders.values():
            while True:
                with sub.handle:
                    taken = sub.handle.take_message(UInt8MultiArray, False)
                if taken is None:
                    break
                self._merge_logs(unpack(taken[0])[3])

    def _merge_logs(self, logs: tuple) -> None:
        if logs and self._logs is not None:
            self._logs.merge(logs)

    def done(self, index: int) -> bool:
        return index in self._done

    def collect(self) -> dict[int, list[Message]]:
        """What the robots sent for the tick, by robot index; the next tick starts empty."""
        out, self._pending, self._done, self.answered = self._pending, {}, set(), set()
        return out

    def destroy(self) -> None:
        self.node.destroy_node()


class _AllReceivers:
    """The batch publisher counts as matched once it has matched every receiving process so far."""

    def __init__(self, publisher, receivers: int):
        self._publisher, self._receivers = publisher, receivers

    def get_subscription_count(self) -> int:
        return int(self._publisher.get_subscription_count() >= self._receivers)
