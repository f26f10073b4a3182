"""The run-wide relay across processes (multi-process mode; hosting/run_wide/relay.py is the relay itself).

A controller process has a relay of its own. Its robot's messages of tick k go to the simulator
on /<robot>/_composed_sim/run_wide, once the robot's nodes have nothing left to do in the tick;
the simulator publishes each tick's batch on /_composed_sim/run_wide in every domain before the
tick's sensors, and a controller process delivers it before the first sensor callback of the tick
runs. Both carry (stamp ns, messages, …), pickled, in a std_msgs/UInt8MultiArray. The robot's part
also says whether its nodes answered the tick (for a robot that answers when published) and
carries its log lines' part for the simulator's console and /rosout.

They carry the calls between places too (hosting/calls/between_places.py): a batch or a round message
of the simulator has the calls for each robot of its domain; the controller process hands its
robot's over as soon as they arrive, runs its nodes until idle and replies with a part that is not
the tick's last (``final``), with the calls they made. The simulator leads the rounds as the
worker host's main process does (hosts/multiprocess/exchange.py).
"""
from __future__ import annotations

import pickle
import time
from array import array
from typing import Callable, Collection, Optional

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.serialization import serialize_message
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import UInt8MultiArray

from composed_sim.ros.robot_settings import quiet_node_options
from composed_sim.hosting.run_wide.relay import Message, RunWideRelay
from composed_sim.hosting.sim_time.timers import clocks_to

BATCH_TOPIC = "/_composed_sim/run_wide"
LINK_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
LAST_WORDS_ACK_S = 2.0      # how long an ending controller process waits for its last part's acknowledgement


def outbox_topic(robot: str) -> str:
    return f"/{robot}/_composed_sim/run_wide"


def pack(stamp_ns: int, messages: list[Message], answered: bool = False, logs: tuple = (), calls=(),
         final: bool = True, notes: Optional[dict] = None) -> UInt8MultiArray:
    """``answered``: a robot's part says whether its nodes published cmd_vel in the tick; ``logs``:
    what its log lines give the simulator's console and /rosout (``NodeLogs.drain``); ``calls``: a
    robot's calls, or the simulator's for each robot ({index: calls}); ``final``: the robot's last
    part of the tick (else its reply to calls); ``notes``: what its nodes made since, for the
    simulator: ``answer``, (type name, answer's bytes or None) of its first cmd_vel publisher (the
    simulator subscribes then, and takes the answer it could not hear yet); ``reads``, {sensor
    topic: how many of its subscriptions read it} (the simulator waits until they are matched);
    ``published``, {topic: messages published there since} (a drone's setpoints, counted: the
    simulator takes that many from DDS before the tick closes)."""
    return UInt8MultiArray(data=array("B", pickle.dumps((stamp_ns, messages, answered, logs, calls, final, notes),
                                                        protocol=pickle.HIGHEST_PROTOCOL)))


def unpack(msg: UInt8MultiArray) -> tuple[int, list[Message], bool, tuple, object, bool, Optional[dict]]:
    return pickle.loads(bytes(msg.data))


class RunWideLink:
    """A controller process's side of the run: it takes each tick's batch from the simulator
    before the robot's first sensor callback of the tick (``before_tick``) and, with ``sends``,
    sends what the robot's nodes published once they are idle (``send``) every tick: the simulator
    waits for it. ``logs``: a forwarding ``NodeLogs``, whose part for the simulator's console and
    /rosout goes along."""

    def __init__(self, context, robot: str, relay: RunWideRelay, *, receives: bool, sends: bool,
                 timeout_s: float, logs=None, calls=None, index: int = 0):
        """``calls``: the process's call relay (hosting/calls/between_places.py), ``index``: its robot's."""
        self._relay, self._timeout_s, self._logs = relay, timeout_s, logs
        self._calls, self._index = calls, index
        self.sends = sends
        self.node = Node("run_wide_link", namespace=f"/{robot}", context=context, **quiet_node_options())
        # Taken by the robot's executor as they come (the link's node is its first), or by
        # ``before_tick`` when a tick's sensors come first.
        self._batches = self.node.create_subscription(UInt8MultiArray, BATCH_TOPIC, self._on_batch, LINK_QOS) \
            if receives else None
        self.reply_due = False       # calls were delivered: reply once the nodes are idle
        self._outbox = self.node.create_publisher(UInt8MultiArray, outbox_topic(robot), LINK_QOS) if sends else None
        self.delivered = -1         # stamp of the last batch delivered
        self.tick = -1              # stamp of the last tick whose sensors arrived
        self.sent = -1              # stamp of the last tick whose messages went out
        self.answered = -1          # stamp of the last tick the robot's nodes published cmd_vel in
        self.answer_type: Optional[str] = None      # a first cmd_vel publisher's type, to tell the simulator
        self._carried: Optional[bytes] = None        # … and its first answer, which the simulator cannot hear yet
        self._held: Optional[tuple] = None           # (publish, message): the pass's last cmd_vel so far
        # Whether cmd_vel is held for ``send_held_answer``: only where the caller drives the executor
        # (the lockstep one), whose passes it sees; a threaded executor's callbacks publish at once.
        self.holds_answers = False
        self.reads: dict[str, int] = {}              # sensor topics read by subscriptions made since: how many
        self._published: dict[str, int] = {}     # counted messages since the last part, by topic (``count``)
        self.clocks: list = []      # the robot's nodes' clocks (sim_time/timers.clocks_to)
        # Where delivered messages' callbacks run: the lockstep executor's ``run_callback`` (as
        # tasks, their callback groups respected), else at once.
        self.run_callback: Optional[Callable[[Callable, object], None]] = None

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
        waits for the answer itself, not only for the sign that the robot is idle). Where the
        robot's part of each tick is sent and its executor is driven pass by pass (the lockstep
        one: ``holds_answers``), what its nodes publish on cmd_vel in one pass goes out once, the
        last, after the pass (``send_held_answer``): in one process
        the simulator takes every copy before the tick closes and keeps the last
        (ros/answer_ledger.py), and over DDS a second copy published a moment after the first
        could arrive after the tick closed on the first."""
        for publisher in publishers:
            publish = publisher.publish

            def noting(msg, publish=publish, publisher=publisher):
                # A lifecycle publisher not activated publishes nothing: no answer.
                if not getattr(publisher, "is_activated", True):
                    return publish(msg)
                if self.answer_type is not None:
                    self._carried = serialize_message(msg)
                if self.sends and self.holds_answers:
                    self._held = (publish, msg)         # noted as the tick's answer when sent
                    return None
                self.answered = self.tick
                return publish(msg)
            publisher.publish = noting

    def send_held_answer(self) -> None:
        """The last cmd_vel the nodes published since the last call, if any, now; one published
        before tick 0's sensors came (a goal sent from a constructor, executed at once) waits for
        them and answers tick 0, as a message handed over in one process does."""
        if self._held is not None and self.tick >= 0:
            (publish, msg), self._held = self._held, None
            self.answered = self.tick
            publish(msg)

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
            self._on_batch(taken[0])

    def _handle(self, msg) -> bool:
        """A batch or a round message of the simulator: its run-wide messages (a batch's) and the
        calls for this robot delivered; True if it brought calls (to be replied to)."""
        stamp, batch, _, _, calls, final, _ = unpack(msg)
        clocks_to(self.clocks, stamp)     # as the tick opens: its calls are served on its time
        if final:                    # a tick's batch (a round message carries calls only)
            self._relay.deliver(batch, run=self.run_callback)
            self.delivered = max(self.delivered, stamp)
        # Its own calls, and what is for every process (what the run's places serve).
        mine = [*calls.get(None, ()), *calls.get(self._index, ())] if calls else []
        if mine and self._calls is not None:
            self._calls.deliver(mine)
        return bool(calls) and self._index in calls      # to be replied to

    def _on_batch(self, msg) -> None:
        if self._handle(msg):
            self.reply_due = True

    def reply(self) -> None:
        """This robot's reply to the calls of a round: the calls its nodes made since."""
        self.reply_due = False
        calls = self._calls.take_outbox() if self._calls is not None else []
        self._outbox.publish(pack(max(self.tick, self.delivered), [], self.answered == self.tick, (), calls,
                                  final=False, notes=self._take_notes()))

    def _take_notes(self) -> Optional[dict]:
        notes = {}
        if self.answer_type is not None:
            notes["answer"] = (self.answer_type, self._carried)
            self.answer_type = self._carried = None
        if self.reads:
            notes["reads"], self.reads = self.reads, {}
        if self._published:
            notes["published"], self._published = self._published, {}
        return notes or None

    def count(self, publishers) -> None:
        """Count what ``publishers`` publish (a drone's setpoints, which the simulator takes from DDS
        at the tick's close): the robot's part says how many, and the simulator waits for them."""
        for publisher in publishers:
            publish = publisher.publish

            def counting(msg, publish=publish, topic=publisher.topic_name):
                self._published[topic] = self._published.get(topic, 0) + 1
                return publish(msg)
            publisher.publish = counting

    def send(self) -> None:
        """What the robot's nodes published in the tick of the last sensors, to the simulator."""
        self.send_held_answer()
        logs = self._logs.drain() if self._logs is not None else ()
        calls = self._calls.take_outbox() if self._calls is not None else []
        self._outbox.publish(pack(self.tick, self._relay.take_outbox(), self.answered == self.tick, logs, calls,
                                  notes=self._take_notes()))
        self.sent = self.tick

    def send_logs(self) -> None:
        """A failing robot's last log lines' part, if any, as its process ends. It waits (boundedly)
        for the simulator to acknowledge it: a reliable message the transport dropped is resent
        only while its writer lives, and the simulator counts a failed robot's lines only once
        its process has ended (under load, one robot's last warning was lost that way)."""
        if self._outbox is not None and self._logs is not None and self._logs.forwarding:
            self._outbox.publish(pack(self.tick, [], False, self._logs.drain()))
            self._outbox.wait_for_all_acked(Duration(seconds=LAST_WORDS_ACK_S))

    def destroy(self) -> None:
        self.node.destroy_node()


class SimulatorLink:
    """The simulator's side of the run-wide relay in one ROS domain (multi-process mode): it
    publishes each tick's batch there and takes what each robot of the domain sent."""

    def __init__(self, context, name: str, logs=None):
        """``logs``: the simulator's ``NodeLogs``, into which the robots' log lines' parts go."""
        self.node = Node(name, context=context, **quiet_node_options())
        self._logs = logs
        self._batches = self.node.create_publisher(UInt8MultiArray, BATCH_TOPIC, LINK_QOS)
        self._receivers = 0
        self._outboxes: dict[int, object] = {}       # robot index in the run → its subscription
        self._pending: dict[int, list[Message]] = {}  # what a robot sent for the open tick so far
        self._done: set[int] = set()                  # robots whose messages of the open tick are in
        self.answered: set[int] = set()               # … of which those that published cmd_vel in it
        self.calls: list = []                         # the calls the robots made (in parts and replies)
        self.replied: set[int] = set()                # robots that replied to the calls they were sent
        self.notes: dict[int, list[dict]] = {}        # what robots' nodes made since (RunWideLink._take_notes)

    def add_robot(self, index: int, robot: str, topics: Collection[str]) -> dict[str, object]:
        """A controller process reported its link's topics: its endpoints on this side, by topic
        (each answers ``get_*_count() >= 1`` once matched, as the start-up check asks)."""
        endpoints = {}
        if BATCH_TOPIC in topics:
            self._receivers += 1
            endpoints[BATCH_TOPIC] = _AllReceivers(self._batches, self._receivers)
        if outbox_topic(robot) in topics:
            sub = self.node.create_subscription(UInt8MultiArray, outbox_topic(robot), lambda msg: None, LINK_QOS)
            self._outboxes[index] = sub
            endpoints[outbox_topic(robot)] = sub
        return endpoints

    @property
    def senders(self) -> list[int]:
        return list(self._outboxes)

    def publish(self, stamp_ns: int, batch: list[Message], calls: Optional[dict] = None) -> None:
        """A tick's batch, with the calls for each robot of the domain ({index: calls}); each robot
        sent calls replies once idle."""
        self.replied -= set(calls or ())
        if self._receivers:
            self._batches.publish(pack(stamp_ns, batch, calls=calls or {}))

    def publish_calls(self, stamp_ns: int, calls: dict) -> None:
        """A round's calls for robots of the domain ({index: calls}); each replies once idle."""
        self.replied -= set(calls)
        self._batches.publish(pack(stamp_ns, [], calls=calls, final=False))

    def take(self, stamp_ns: int, waiting: Collection[int], replies: bool = False) -> None:
        """Take what arrived from the robots ``waiting`` (indices) for ticks up to ``stamp_ns``
        (``replies``: their replies to a round's calls, before or after their last part)."""
        for index in waiting:
            sub = self._outboxes[index]
            while index not in (self.replied if replies else self._done):
                with sub.handle:
                    taken = sub.handle.take_message(UInt8MultiArray, False)
                if taken is None:
                    break
                stamp, messages, answered, logs, calls, final, notes = unpack(taken[0])
                self._merge_logs(logs)
                if notes:
                    self.notes.setdefault(index, []).append(notes)
                self.calls += calls
                if not final:                       # a reply to calls
                    self.replied.add(index)
                    if answered:
                        self.answered.add(index)
                    continue
                self._pending.setdefault(index, []).extend(messages)
                if stamp >= stamp_ns:
                    self._done.add(index)
                    if answered:
                        self.answered.add(index)

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
