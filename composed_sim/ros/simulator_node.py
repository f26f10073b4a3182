"""The simulator node: publishes each tick's sensors and /clock, collects the controllers' answers.

The node is the only ROS-facing piece of the simulator. It holds no simulation state: the host
hands it a SensorFrame to publish and reads back the commands as arrays.
"""
from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Collection, Mapping, Optional, Sequence

import numpy as np
from rclpy.context import Context
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from composed_sim.devices import DEVICES
from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import DevicePublisher, GroupPlan, NodeRobots, Outgoing
from composed_sim.ros import contract as c, decoding
from composed_sim.ros.answer_ledger import AnswerLedger
from composed_sim.ros.answer_subscription import AnswerSubscription, ControllerPublishers, publisher_gid
from composed_sim.ros.clock_watch import ClockWatch
from composed_sim.ros.command_inbox import CommandInbox
from composed_sim.ros.driven_clocks import DrivenClocks
from composed_sim.ros.robot_settings import quiet_node_options
from composed_sim.ros.robot_taps import RobotTaps
from composed_sim.ros.taps import MessageTap
from composed_sim.ros.topic import message_class
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import Lockstep
if TYPE_CHECKING:   # only a type here: a controller process must not import the physics
    from composed_sim.core.simulation import SensorFrame


class AnswerTypeError(Exception):
    """A controller publishes a type on cmd_vel that the topic contract does not accept."""


ACCEPTED_ANSWERS: dict[str, type] = {c.type_name(t): t for t in c.ANSWER_TYPES.values()}


class SimulatorNode(Node):
    """Sensor publishers and command subscriptions for a set of robots, in one node.

    One node serves every robot of a participant group in composed mode; in multi-process mode
    there is one per ROS domain, each serving that domain's robots (``rows``: their rows in the
    simulation's arrays). The answers to each tick are kept by its ``AnswerLedger``
    (ros/answer_ledger.py), whose arrays it shows (``answered``, ``failed`` …).

    LED and rab_tx commands go to its inbox (ros/command_inbox.py), drained at the act phase.
    """

    def __init__(self, names: list[str], models: list[RobotModel], *, context: Context,
                 tick_ns: int, rows: Optional[np.ndarray] = None, node_name: str = "composed_sim",
                 lockstep: Optional[Lockstep] = None, devices: Optional[Sequence[Collection[str]]] = None,
                 rab_payload_bytes: int = 10, publish_clock: bool = True,
                 answer_types: Optional[Sequence[Optional[type]]] = None,
                 answers_every_ticks: Optional[Sequence[int]] = None, global_tf: Optional[Sequence[bool]] = None,
                 answers_when_published: Optional[Sequence[bool]] = None,
                 answers_by_firmware: Optional[Sequence[bool]] = None):
        """``lockstep``, ``answers_every_ticks``, ``answers_when_published``, ``answers_by_firmware``
        (a drone's: never waited for): the ledger's (ros/answer_ledger.py). ``devices``: per robot,
        the devices whose topics it has (None: its model's). ``rab_payload_bytes``: the world's
        range_and_bearing.payload_bytes. ``publish_clock``: False where another node of this process
        and domain publishes it. ``answer_types``: per robot, its controller's cmd_vel type (of
        ``contract.ANSWER_TYPES``), or None to read it from the graph (``detect_answer_types``); None:
        TwistStamped for all. ``global_tf``: per robot, its frames on /tf and /tf_static rather than
        its own /<robot>/tf. A drone's Crazyswarm2 endpoints are ``drones`` (ros/crazyflie/), set by the host."""
        super().__init__(node_name, context=context, **quiet_node_options())
        n = len(names)
        rows = np.arange(n) if rows is None else np.asarray(rows)
        if len(rows) != n:
            raise ValueError(f"{n} robots but {len(rows)} rows")
        self._names = names
        self._index = {name: i for i, name in enumerate(names)}
        self._models, self._tick_ns = models, tick_ns
        self._ledger = AnswerLedger(names, rows, lockstep, answers_every_ticks, answers_when_published,
                                    answers_by_firmware)
        self.drones = None           # the drones' Crazyswarm2 endpoints beside this node (the host's)
        ledger = self._ledger           # its arrays, read (and filled) in place
        self.rows, self.when_published, self.by_firmware, self.violations, self.on_failed = \
            ledger.rows, ledger.when_published, ledger.by_firmware, ledger.violations, ledger.on_failed
        self.linear, self.angular, self.answered, self.rejected, self.failed = \
            ledger.linear, ledger.angular, ledger.answered, ledger.rejected, ledger.failed
        self._clock_pub = self.create_publisher(Clock, c.CLOCK_TOPIC, 10, event_callbacks=c.PUBLISHER_EVENTS) if publish_clock else None
        self._clock_msg, self.clocks = Clock(), DrivenClocks(tick_ns)     # the hosted nodes' clocks
        self._clock_watch = ClockWatch(self, publisher_gid(self._clock_pub)) if publish_clock else None
        self._taps = RobotTaps(names)
        self._run_wide_publishers: dict[str, object] = {}    # topic → its publisher (mirror_run_wide)
        self._devices = [frozenset(m.default_devices) for m in models] if devices is None \
            else [frozenset(d) for d in devices]
        if len(self._devices) != n:
            raise ValueError(f"{n} robots but devices for {len(self._devices)}")
        # One publisher set per device that any of these robots runs (devices/).
        robots = NodeRobots(names, models, self._devices, tick_ns, rab_payload_bytes, global_tf)
        self._device_publishers: list[DevicePublisher] = [d.publisher(self, robots) for d in DEVICES
                                                          if robots.running(d.name)]
        # Every sensor publisher of each robot (a robot is connected once any has a subscriber).
        self._sensor_pubs = [[p.pubs[i] for p in self._device_publishers if p.pubs[i] is not None] for i in range(n)]
        self._plans: Optional[list[GroupPlan]] = None   # built from the first frame's groups
        self._cmd_subs: list[Optional[AnswerSubscription]] = [None] * n   # per robot, once its answer type is known
        self._answer_types: list[Optional[type]] = [c.msg_type(c.CMD_VEL)] * n if answer_types is None \
            else list(answer_types)
        self._controllers = ControllerPublishers(self, self._cmd_subs, self._answer_types)
        self._foreign_noted: set[tuple[int, bytes]] = set()   # (robot, GID) recorded this tick
        for i, msg_type in enumerate(self._answer_types):
            if msg_type is not None:
                self._subscribe_answers(i, msg_type)
        self._inbox = CommandInbox(node_name, context, names, models, self._devices, rab_payload_bytes,
                                   self.rows, ledger, self._taps)
        # Drained by the host at the act phase (ros/command_inbox.py).
        self.take_led_commands, self.take_rab_payloads = self._inbox.take_led_commands, self._inbox.take_rab_payloads

    def _subscribe_answers(self, i: int, msg_type: type) -> None:
        on_answer = self._on_cmd_vel if msg_type is c.msg_type(c.CMD_VEL) else self._on_unstamped_cmd_vel
        self._answer_types[i] = msg_type
        self._cmd_subs[i] = AnswerSubscription(self, msg_type, c.topic_name(self._names[i], c.CMD_VEL), c.QOS,
                                               functools.partial(on_answer, i))

    def detect_answer_types(self, robots: Optional[Collection[str]] = None) -> None:
        """Subscribe to the cmd_vel of each robot (of ``robots``, or all) whose answer type is not
        known yet, with the type its controller's publisher has in the ROS graph (distributed
        mode, and a controller process whose cmd_vel publisher came after its start-up report). A
        type the contract does not accept raises ``AnswerTypeError``."""
        for i in [i for i, t in enumerate(self._answer_types) if t is None]:
            if robots is not None and self._names[i] not in robots:
                continue
            topic = c.topic_name(self._names[i], c.CMD_VEL)
            if found := sorted({info.topic_type for info in self.get_publishers_info_by_topic(topic)}):
                wrong = [name for name in found if name not in ACCEPTED_ANSWERS]
                self.take_answers_as(self._names[i], (wrong or found)[0])

    def take_answers_as(self, robot: str, type_name: str) -> None:
        """Subscribe to ``robot``'s cmd_vel with ``type_name`` (``geometry_msgs/msg/Twist``), what
        its controller publishes, unless its answer type is known already. A type the contract
        does not accept raises ``AnswerTypeError``."""
        i = self._index[robot]
        if self._answer_types[i] is not None:
            return
        if type_name not in ACCEPTED_ANSWERS:
            raise AnswerTypeError(f"the controller of {robot} publishes {type_name} on "
                                  f"{c.topic_name(robot, c.CMD_VEL)}; the topic contract accepts "
                                  f"{' or '.join(ACCEPTED_ANSWERS)}")
        self._subscribe_answers(i, ACCEPTED_ANSWERS[type_name])

    def another_simulator(self) -> Optional[str]:
        """Another publisher of /clock in this node's domain (ros/clock_watch.py), or None; a node
        that does not publish /clock (the others of its process and domain) never finds one."""
        return None if self._clock_watch is None else self._clock_watch.another_simulator()

    def note_controllers(self, gids: Mapping[str, Collection[bytes]]) -> None:
        """The GIDs of each robot's controller's cmd_vel publishers (``cmd_vel_gids``), from the
        host before tick 0: the only publishers whose answers move the robot (docs/faults.md)."""
        self._controllers.set([frozenset(gids[name]) if gids.get(name) else None for name in self._names])

    def note_controller(self, robot: str, gids: Collection[bytes]) -> None:
        """``note_controllers`` for one robot, whose nodes made a cmd_vel publisher after tick 0's
        set-up (a lifecycle node's, in its configure transition)."""
        self._controllers.set_one(self._index[robot], frozenset(gids) or None)

    def inbox_subscriptions(self) -> list:
        """The LED and rab_tx subscriptions, drained at the act phase (``take_led_commands``)."""
        return self._inbox.subscriptions

    def sensor_publishers(self) -> list:
        """Every robot's sensor publishers, robot by robot."""
        return [p for pubs in self._sensor_pubs for p in pubs]

    def device_publishers(self) -> list[DevicePublisher]:
        """The publishers of each device's topics, which ask DDS for readers while ``checking``."""
        return list(self._device_publishers)

    def answer_subscription(self, robot: str) -> Optional[AnswerSubscription]:
        """``robot``'s cmd_vel subscription (None until its answer type is known)."""
        return self._cmd_subs[self._index[robot]]

    def endpoints_by_topic(self) -> dict:
        """The simulator's side of each robot topic, by topic name: sensor publishers, cmd_vel
        subscriptions and the LED and rab_tx inbox's subscriptions (for matching checks)."""
        found = [*self.publishers, *(s for s in self._cmd_subs if s is not None), *self._inbox.node.subscriptions]
        return {e.topic_name: e for e in found if e.topic_name != c.CLOCK_TOPIC}

    def robot_endpoints(self, robot: str) -> list:
        """``endpoints_by_topic``'s endpoints of one robot: its sensor publishers, its cmd_vel
        subscription (once its answer type is known), its LED and rab_tx subscriptions."""
        i = self._index[robot]
        return [*self._sensor_pubs[i], *(e for e in (self._cmd_subs[i], *self._inbox.robot_subscriptions(i))
                                         if e is not None)]

    def _from_controller(self, i: int, gid: bytes) -> bool:
        """Is this answer from robot i's controller? One from any other publisher is rejected and
        recorded once per tick and publisher; it does not count against the robot's
        max_violations (its controller did nothing wrong)."""
        if self._controllers.accepts(i, gid):
            return True
        ledger = self._ledger
        with ledger.lock:
            if (i, gid) not in self._foreign_noted:
                self._foreign_noted.add((i, gid))
                ledger.record(ledger.current_tick, i, f"cmd_vel from {self._controllers.describe(i, gid)}, which "
                              f"is not {self._names[i]}'s controller: rejected", counts=False)
        return False

    def create_robot_publisher(self, robot: str, topic: c.Topic):
        """The publisher of ``robot``'s ``topic``, for its device (devices/)."""
        return self.create_topic_publisher(c.topic_name(robot, topic), topic)

    def create_topic_publisher(self, name: str, topic: c.Topic):
        """A publisher of ``topic``'s type and QoS on ``name``, for a device (devices/)."""
        return self.create_publisher(c.msg_type(topic), name, c.qos(topic), event_callbacks=c.PUBLISHER_EVENTS)

    def set_message_tap(self, tap: MessageTap) -> None:
        """Hand every per-robot message the tap wants (sensors out, answers in) to it, e.g. a bag."""
        self._taps.set(tap)
        for publisher in self._device_publishers:     # a recorded topic is published from now on
            publisher.publish_check()

    def taps(self, topic: c.Topic, i: int) -> bool:
        """Is robot i's ``topic`` recorded? (For its device's publisher.)"""
        return self._taps.wants(topic, i)

    def tap_messages(self, topic: c.Topic, rows: Sequence[int], messages: Sequence, stamp_ns: int) -> None:
        """Robots ``rows``' messages on ``topic`` (``messages[j]`` robot ``rows[j]``'s) to the tap."""
        self._taps.messages(topic, rows, messages, stamp_ns)

    def mirror_run_wide(self, batch, stamp_ns: int) -> None:
        """A tick's run-wide messages (hosting/run_wide/relay.py) on the wire, for processes outside the run
        (a second rclpy process, a recorder), and to the tap: the hosted nodes get them from the
        relay, never from these publishers. One simulator node of the run does this."""
        for topic, type_name, data in batch:
            publisher = self._run_wide_publishers.get(topic)
            if publisher is None:
                publisher = self._run_wide_publishers[topic] = self.create_publisher(
                    message_class(type_name), topic, c.QOS)
            publisher.publish(data)
            if self._taps.tap is not None and self._taps.tap.wants(topic):
                self._taps.write(topic, type_name, data, stamp_ns)

    @property
    def robots(self) -> list[str]:
        """The names of this node's robots, in row order."""
        return self._names

    def row_of(self, robot: str) -> int:
        """``robot``'s index among this node's robots (its row in ``failed``, ``answered`` …)."""
        return self._index[robot]

    def mark_failed(self, robot: str, reason: str) -> None:
        """Stop a robot for good (its controller is gone, hung or past max_violations): recorded
        once, then stopped (zero command) every tick, never waited for; its sensors are no longer
        published."""
        self._ledger.mark_failed(robot, reason)

    def reject_answer(self, robot: str, reason: str) -> None:
        """Settle a robot's part of the open tick as a violation (ros/answer_ledger.py)."""
        self._ledger.reject_answer(robot, reason)

    def take_ready_answers(self) -> int:
        """Take the answers waiting on the cmd_vel subscriptions now, from this thread (a
        multi-threaded executor takes them on its own threads, when it gets to them)."""
        return sum(sub.dispatch_ready() for sub in self._cmd_subs if sub is not None)

    def answer_later(self, robots: Collection[str], until_tick: Optional[int] = None) -> None:
        """Robots whose nodes will publish cmd_vel later: quiet until their first answer, or
        ``until_tick`` (ros/answer_ledger.py)."""
        self._ledger.answer_later(robots, until_tick)

    def settle_idle(self, robots: Optional[Collection[str]] = None) -> int:
        """The quiet robots whose nodes are done with the open tick keep their last command
        (ros/answer_ledger.py); how many."""
        return self._ledger.settle_idle(robots)

    # --- the tick exchange ----------------------------------------------------------------

    def open_tick(self, tick: int) -> None:
        """Open tick ``tick``'s answer window (once), before anything of the tick reaches the
        robots' nodes: a node woken as its clock moves to the tick answers it."""
        key = c.stamp_key(c.stamp_of(tick, self._tick_ns))
        if self._ledger.current_key == key:
            return
        if not self._controllers.noted:
            self._controllers.note()
        with self._ledger.lock:
            self._foreign_noted.clear()
            self._ledger.open_tick(tick, key)

    def publish_tick(self, frame: SensorFrame) -> None:
        """Publish /clock and every robot's sensors for ``frame.tick``; open the answer window."""
        stamp = c.stamp_of(frame.tick, self._tick_ns)
        key = c.stamp_key(stamp)
        self.open_tick(frame.tick)
        if self._clock_pub is not None:
            self._clock_msg.clock = stamp
            self._clock_pub.publish(self._clock_msg)
        self.clocks.move_to(frame.tick)
        failed = self.failed.tolist()
        out = Outgoing(stamp.sec, stamp.nanosec, key, cdr.stamp_bytes(stamp.sec, stamp.nanosec),
                       failed, failed.count(True))
        for plan in self._plans if self._plans is not None else self._make_plans(frame):
            for publisher in self._device_publishers:
                if publisher.device in plan.devices:
                    publisher.publish(plan, frame, out)
        for publisher in self._device_publishers:
            publisher.finish_tick(out)
        if self.drones is not None:
            self.drones.publish_status(frame.tick, frame.supervisor_info)

    def publish_clock(self, tick: int) -> None:
        """/clock alone, for the state after the last tick: its sensors are never published (no
        controller answers it), but the recordings and the markers show it, and so does the clock."""
        if self._clock_pub is not None:
            self._clock_msg.clock = c.stamp_of(tick, self._tick_ns)
            self._clock_pub.publish(self._clock_msg)

    def _make_plans(self, frame: SensorFrame) -> list[GroupPlan]:
        """Which of this node's robots are in which group of the frame (fixed for a run)."""
        self._plans = []
        for gi, g in enumerate(frame.groups):
            local = np.flatnonzero((self.rows >= g.robots.start) & (self.rows < g.robots.stop))
            if len(local):
                within = self.rows[local] - g.robots.start
                self._plans.append(GroupPlan(gi, self._models[local[0]], self.rows[local], local, within,
                                             self._devices[local[0]]))
        return self._plans

    def unmatched_robots(self) -> list[str]:
        """Robots whose controller is not connected yet: no publisher matched on its cmd_vel, or no
        subscriber on any of its sensors. Matched counts are local to each endpoint (O(1))."""
        self.detect_answer_types()
        return [name for i, name in enumerate(self._names) if not self._ledger.by_firmware[i] and (
                self._cmd_subs[i] is None or self._cmd_subs[i].get_publisher_count() < 1
                or not any(p.get_subscription_count() >= 1 for p in self._sensor_pubs[i]))]

    def connection_of(self, robot: str) -> str:
        """What this node sees of ``robot``'s controller: its cmd_vel publisher and which of its
        sensor topics have a subscriber, for a start-up error that says what is missing."""
        i = self._index[robot]
        cmd = self._cmd_subs[i]
        answer = "a cmd_vel publisher" if cmd is not None and cmd.get_publisher_count() >= 1 else "no cmd_vel publisher"
        heard = [p.topic_name for p in self._sensor_pubs[i] if p.get_subscription_count() >= 1]
        return (f"{robot}: {answer}, "
                + (f"subscribers on {', '.join(heard)}" if heard else "no subscriber on any of its sensors "
                   f"({', '.join(p.topic_name for p in self._sensor_pubs[i])})"))

    def wait_for_answers(self, timeout_s: float) -> bool:
        return self._ledger.wait_for_answers(timeout_s)

    @property
    def all_answered(self) -> bool:
        return self._ledger.all_answered

    @property
    def answered_count(self) -> int:
        return self._ledger.answered_count

    def take_carried_answer(self, robot: str, data: bytes) -> None:
        """An answer that came another way than its subscription: a controller process's first,
        published before this node subscribed (its type was not known yet), carried with the
        robot's part of the tick (hosting/run_wide/link.py)."""
        i = self._index[robot]
        on_answer = self._on_cmd_vel if self._answer_types[i] is c.msg_type(c.CMD_VEL) else self._on_unstamped_cmd_vel
        on_answer(i, data, None)

    def _on_unstamped_cmd_vel(self, i: int, data: bytes, gid: bytes) -> None:
        """A Twist answers the tick whose sensors it follows: the open one. One that arrives while
        no tick is open answers a tick already closed (whose miss is recorded): it is dropped,
        unless its robot answers when published (``AnswerLedger.hold``)."""
        if not self._from_controller(i, gid):
            return
        linear, angular = decoding.decode_unstamped_answer_cdr(data)
        self._on_arrival(i, linear, angular, data)

    def _on_cmd_vel(self, i: int, data: bytes, gid: bytes) -> None:
        """A TwistStamped answers the tick its stamp names; one never stamped (zero: ROS's unset
        time, as a node written for a base that ignores stamps leaves it) answers as a Twist does."""
        if not self._from_controller(i, gid):
            return
        key, linear, angular = decoding.decode_answer_cdr(data)
        if key == 0:
            self._on_arrival(i, linear, angular, data)
            return
        with self._ledger.lock:
            self._answer(i, key, linear, angular, data)

    def _on_arrival(self, i: int, linear: float, angular: float, data: bytes) -> None:
        """An answer matched to a tick by its arrival: the open tick's, or, with none open, held."""
        with self._ledger.lock:
            key = self._ledger.current_key
            if key < 0:
                self._ledger.hold(i, linear, angular)
                return
            self._answer(i, key, linear, angular, data)

    def _answer(self, i: int, key: int, linear: float, angular: float, data: bytes) -> None:
        """Called with the ledger's lock held."""
        if not self._ledger.accepts(i, key, self._tick_ns):
            if key != self._ledger.current_key and key <= self._ledger.tick_key:     # a closed tick's
                self._ledger.hold(i, linear, angular)
            return
        self._taps.message(c.CMD_VEL, i, data, key, self._answer_types[i])
        self._ledger.take(i, linear, angular)

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        """End the answer window; this node's robots' commands into ``commands`` (ros/answer_ledger.py)."""
        for sub in self._cmd_subs:
            if sub is not None and sub.inbox.queue:
                sub.take_handed_over()
        self._ledger.close_tick(fallback, previous, commands)

    def destroy_node(self) -> None:
        for sub in self._cmd_subs:
            if sub is not None:
                sub.destroy(self)
        self._inbox.destroy()
        super().destroy_node()
