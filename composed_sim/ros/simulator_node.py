"""The simulator node: publishes each tick's sensors and /clock, collects the controllers' answers.

The node is the only ROS-facing piece of the simulator. It holds no simulation state: the host
hands it a SensorFrame to publish and reads back the commands as arrays.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Optional, Protocol, Sequence

import numpy as np
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM
from rclpy.time import Time as RosTime
from rosgraph_msgs.msg import Clock

from composed_sim.core.robot_models import RobotModel
from composed_sim.world.schema import Lockstep
if TYPE_CHECKING:   # only a type here: a controller process must not import the physics
    from composed_sim.core.simulation import SensorFrame
from composed_sim.ros import contract as c



class MessageTap(Protocol):
    def wants(self, topic: str) -> bool: ...
    def write_serialized(self, topic: str, msgtype: str, data: bytes, stamp_ns: int) -> object: ...


FAILED = "controller failed: "    # how the one violation that fails a robot begins
LATE_LEDS = "leds answering an earlier tick arrived after that tick closed: applied one tick late"


@dataclass
class Violation:
    tick: int
    robot: str
    reason: str


def quiet_node_options(parameter_overrides: Sequence[Parameter] = ()) -> dict:
    """Node options for thousands of nodes: no parameter services, no /rosout and no
    ~/get_type_description service. Each would add endpoints, and every new endpoint is
    announced to the whole participant, so node creation would grow quadratically."""
    return dict(start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[*parameter_overrides,
                                     Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])


class SimulatorNode(Node):
    """Sensor publishers and command subscriptions for a set of robots, in one node.

    One node serves every robot in composed mode; in multi-process mode there is one per ROS
    domain, each serving that domain's robots (``rows``: their rows in the simulation's arrays).

    Answers (``cmd_vel``) arrive through executor callbacks, possibly on worker threads; the
    host waits on ``wait_for_answers``. LED commands go to a separate inbox node that is never
    added to an executor and is drained by the host at the act phase, so an LED change
    published before a tick's answer always lands on the same tick, whatever the executor.
    """

    def __init__(self, names: list[str], models: list[RobotModel], *, context: Context,
                 tick_ns: int, rows: Optional[np.ndarray] = None, node_name: str = "composed_sim",
                 lockstep: Optional[Lockstep] = None):
        """``lockstep``: the world's fault policy (unresponsive_after_s, max_violations); None:
        robots are never failed for being unresponsive or for their violations."""
        super().__init__(node_name, context=context, **quiet_node_options())
        self._names = names
        self._index = {name: i for i, name in enumerate(names)}
        self._unresponsive_s = math.inf if lockstep is None else lockstep.unresponsive_s
        self._max_violations = None if lockstep is None else lockstep.max_violations
        self._models = models
        self._tick_ns = tick_ns
        n = len(names)
        self.rows = np.arange(n) if rows is None else np.asarray(rows)
        if len(self.rows) != n:
            raise ValueError(f"{n} robots but {len(self.rows)} rows")
        self._inbox = Node(node_name + "_inbox", context=context, **quiet_node_options())
        self._clock_pub = self.create_publisher(Clock, c.CLOCK_TOPIC, 10)
        self._clock_msg = Clock()
        self._driven_clocks = []
        self._tap: Optional[MessageTap] = None

        # Messages go out and answers come in as serialized bytes (cdr.py: a quarter of the cost).
        self._proximity_pubs, self._light_pubs, self._blob_pubs = [], [], []
        self._proximity_enc, self._light_enc, self._blob_enc = [], [], []
        self._led_subs, self._cmd_subs = [], []
        for i, (name, model) in enumerate(zip(names, models)):
            self._proximity_pubs.append(self.create_publisher(c.PROXIMITY.msg_type, c.topic_name(name, c.PROXIMITY), c.QOS))
            self._light_pubs.append(self.create_publisher(c.LIGHT.msg_type, c.topic_name(name, c.LIGHT), c.QOS))
            self._blob_pubs.append(self.create_publisher(c.BLOBS.msg_type, c.topic_name(name, c.BLOBS), c.QOS))
            self._proximity_enc.append(c.proximity_encoder(model, name))
            self._light_enc.append(c.light_encoder(model, name))
            self._blob_enc.append(c.blobs_encoder(name))
            self._cmd_subs.append(self.create_subscription(
                c.CMD_VEL.msg_type, c.topic_name(name, c.CMD_VEL), lambda data, i=i: self._on_cmd_vel(i, data),
                c.QOS, raw=True))
            self._led_subs.append(self._inbox.create_subscription(
                c.LEDS.msg_type, c.topic_name(name, c.LEDS), lambda msg: None, c.QOS))

        # Answers to the current tick, written by callbacks (any thread), read by the host.
        self.linear = np.zeros(n)       # [n] m/s
        self.angular = np.zeros(n)      # [n] rad/s
        self.answered = np.zeros(n, dtype=bool)  # the robot's part of this tick is settled
        self.rejected = np.zeros(n, dtype=bool)  # … by a violation: it gets the fallback
        self.failed = np.zeros(n, dtype=bool)    # stopped for good: not waited for, zero command
        self.on_failed: list[Callable[[str], None]] = []   # hosts stop what is left of a failed controller
        self._violation_counts = np.zeros(n, dtype=int)
        self._last_accepted_s = np.full(n, math.inf)     # monotonic time of each robot's last good answer
        # Re-entrant: a violation recorded under the lock may fail its robot (max_violations).
        self._lock = threading.RLock()
        self._all_answered = threading.Event()
        self._n_answered = 0
        self._n_expected = n
        self._current_key = -1          # stamp (ns) answers must carry; -1 once the window closed
        self._tick_key = 0              # stamp (ns) of the last published tick
        self._opened_ns: Optional[int] = None
        self._current_tick = -1
        self.violations: list[Violation] = []

    def drive_clock_of(self, node: Node) -> None:
        """Set a node's clock to sim time at each tick directly: a hosted node then sees sim time
        without its own /clock subscription (N deliveries per tick); /clock is still published."""
        clock = node.get_clock()
        clock._set_ros_time_is_active(True)
        self._driven_clocks.append(clock)

    def set_message_tap(self, tap: "MessageTap") -> None:
        """Hand every per-robot message the tap wants (sensors out, answers in) to it, e.g. a bag."""
        self._tap_lock = threading.Lock()
        self._tap = tap
        self._tapped = {topic.name: [tap.wants(c.topic_name(name, topic)) for name in self._names]
                        for topic in c.TOPICS.values()}

    def _tap_message(self, topic: c.Topic, i: int, data: bytes, stamp_ns: int) -> None:
        if self._tap is not None and self._tapped[topic.name][i]:
            with self._tap_lock:   # answers may arrive on executor worker threads
                self._tap.write_serialized(c.topic_name(self._names[i], topic), c.type_name(topic.msg_type),
                                           data, stamp_ns)

    def mark_failed(self, robot: str, reason: str) -> None:
        """Stop a robot for good (its controller is gone, hung or past max_violations): recorded
        once, then stopped (zero command) every tick, never waited for; its sensors are no longer
        published."""
        with self._lock:
            self._fail(self._index[robot], reason)

    def reject_answer(self, robot: str, reason: str) -> None:
        """Settle a robot's part of the open tick as a violation: it gets the fallback, whatever
        it answered or will answer to this tick (e.g. its callback overran the watchdog)."""
        i = self._index[robot]
        with self._lock:
            if self._current_key < 0 or self.failed[i]:
                return
            self.rejected[i] = True
            self._settle(i)
            self._record(self._current_tick, i, reason)

    def _settle(self, i: int) -> None:
        if not self.answered[i]:
            self.answered[i] = True
            self._n_answered += 1
            if self._n_answered >= self._n_expected:
                self._all_answered.set()

    def _fail(self, i: int, reason: str) -> None:
        if self.failed[i]:
            return
        self.failed[i] = True
        self._record(self._current_tick, i, FAILED + reason)
        if not self.answered[i]:
            self._n_expected -= 1
            if self._n_answered >= self._n_expected:
                self._all_answered.set()
        for hook in self.on_failed:
            hook(self._names[i])

    # --- the tick exchange ----------------------------------------------------------------

    def publish_tick(self, frame: SensorFrame) -> None:
        """Publish /clock and every robot's sensors for ``frame.tick``; open the answer window."""
        stamp = c.stamp_of(frame.tick, self._tick_ns)
        with self._lock:
            self.answered[:] = False
            self.rejected[:] = False
            self._n_answered = 0
            self._n_expected = int(np.count_nonzero(~self.failed))
            if self._n_expected == 0:
                self._all_answered.set()
            else:
                self._all_answered.clear()
            self._current_key = self._tick_key = c.stamp_key(stamp)
            self._current_tick = frame.tick
            # Wall time the sensors went out (DDS source timestamps use it); nothing precedes tick 0.
            self._opened_ns = time.time_ns() if frame.tick > 0 else None
            if frame.tick == 0:   # unresponsiveness counts from the first tick on
                self._last_accepted_s[:] = time.monotonic()
        self._clock_msg.clock = stamp
        self._clock_pub.publish(self._clock_msg)
        now = RosTime.from_msg(stamp)
        for clock in self._driven_clocks:
            clock.set_ros_time_override(now)
        blobs = frame.blobs
        points = c.blob_points(blobs.angles, blobs.distances, blobs.colors).tobytes()
        point_size = c.BLOB_DTYPE.itemsize
        offsets = blobs.offsets
        proximity, distances, light = frame.proximity, frame.proximity_distances, frame.light
        sec, nanosec = stamp.sec, stamp.nanosec
        stamp_ns = self._current_key
        for i, row in enumerate(self.rows):
            if self.failed[i]:
                continue
            data = self._proximity_enc[i].encode(sec, nanosec, proximity[row], distances[row])
            self._proximity_pubs[i].publish(data)
            self._tap_message(c.PROXIMITY, i, data, stamp_ns)
            data = self._light_enc[i].encode(sec, nanosec, light[row])
            self._light_pubs[i].publish(data)
            self._tap_message(c.LIGHT, i, data, stamp_ns)
            first, end = offsets[row], offsets[row + 1]
            data = self._blob_enc[i].encode(sec, nanosec, points[first * point_size:end * point_size], end - first)
            self._blob_pubs[i].publish(data)
            self._tap_message(c.BLOBS, i, data, stamp_ns)

    def unmatched_robots(self) -> list[str]:
        """Robots whose controller is not connected yet: no publisher matched on its cmd_vel, or no
        subscriber on any of its sensors. Matched counts are local to each endpoint (O(1))."""
        return [name for i, name in enumerate(self._names)
                if self._cmd_subs[i].get_publisher_count() < 1
                or not any(p[i].get_subscription_count() >= 1
                           for p in (self._proximity_pubs, self._light_pubs, self._blob_pubs))]

    def wait_for_answers(self, timeout_s: float) -> bool:
        return self._all_answered.wait(timeout_s)

    @property
    def all_answered(self) -> bool:
        return self._all_answered.is_set()

    @property
    def answered_count(self) -> int:
        return self._n_answered

    def _on_cmd_vel(self, i: int, data: bytes) -> None:
        key, linear, angular = c.decode_answer_cdr(data)
        with self._lock:
            if self.failed[i]:
                return
            if key != self._current_key:
                # An answer to an earlier tick comes from a robot whose miss of that tick is
                # recorded already; any other stamp is a contract violation of its own.
                if not (key <= self._tick_key and key % self._tick_ns == 0):
                    self._record(self._current_tick, i, f"answer stamped {key} ns answers no tick "
                                 f"published so far (the last is {self._tick_key} ns)")
                return
            if self.answered[i]:
                return  # a second answer to the same tick, or one already rejected: the first counts
            self._tap_message(c.CMD_VEL, i, data, key)
            if not (math.isfinite(linear) and math.isfinite(angular)):
                self.rejected[i] = True
                self._record(self._current_tick, i, f"non-finite velocity command rejected "
                             f"(linear {linear}, angular {angular})")
            else:
                self.linear[i] = linear
                self.angular[i] = angular
                self._last_accepted_s[i] = time.monotonic()
            self._settle(i)

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        """End the answer window and write this node's robots' commands into ``commands``
        (linear [N], angular [N], indexed by simulation row). Robots that did not answer get the
        fallback (zero, or ``previous``), recorded as a violation unless already failed."""
        with self._lock:
            self._current_key = -1   # later answers to this tick are stale
            tick = self._current_tick
            for i in np.flatnonzero(~self.answered & ~self.failed):
                self._record(tick, i, "no answer before the watchdog")
            good = self.answered & ~self.rejected & ~self.failed
            now = time.monotonic()
            for i in np.flatnonzero(~good & (now - self._last_accepted_s >= self._unresponsive_s)):
                self._fail(i, f"unresponsive: no accepted answer for {now - self._last_accepted_s[i]:.1f} s")
            linear, angular = self.linear.copy(), self.angular.copy()
            stopped = self.failed.copy()
        bad = ~good & ~stopped
        if fallback == "previous":
            linear[bad], angular[bad] = previous[0][self.rows[bad]], previous[1][self.rows[bad]]
        else:
            linear[bad], angular[bad] = 0.0, 0.0
        linear[stopped], angular[stopped] = 0.0, 0.0
        commands[0][self.rows] = linear
        commands[1][self.rows] = angular

    def take_led_commands(self) -> dict[int, np.ndarray]:
        """Drain the LED inbox: the latest valid colours per simulation row that sent any.

        A controller publishes ``leds`` before its ``cmd_vel``, but these are two DDS writers
        and DDS orders samples per writer only. Inside one participant (composed mode) delivery
        is synchronous, so the order holds. Across processes both samples go to the same locator
        and are received in order by one transport thread (0 late LEDs in 34,000 robot-ticks
        measured); only a lost LED sample, re-sent at the writer's next heartbeat (~3 s), could
        land after its tick closed. The sample's source timestamp tells that for sure (same
        host clock): an LED published before this tick's sensors went out answers an earlier
        tick. It is still applied (it is the latest colour) and recorded as a violation, so
        "same world and seed ⇒ same trajectories unless a violation is recorded" holds.
        """
        out = {}
        for i, sub in enumerate(self._led_subs):
            while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
                msg, info = taken
                if self.failed[i]:
                    continue
                if self._tap is not None and self._tapped[c.LEDS.name][i]:
                    self._tap_message(c.LEDS, i, serialize_message(msg), self._tick_key)
                with self._lock:
                    if self._opened_ns is not None and info["source_timestamp"] < self._opened_ns:
                        self._record(self._current_tick, i, LATE_LEDS)
                    try:
                        out[int(self.rows[i])] = c.decode_leds(msg, self._models[i].n_leds)
                    except ValueError as e:
                        self._record(self._current_tick, i, f"leds: {e}")
        return out

    def _record(self, tick: int, i: int, reason: str) -> None:
        """Called with the lock held."""
        self.violations.append(Violation(tick, self._names[i], reason))
        self._violation_counts[i] += 1
        if self._max_violations is not None and self._violation_counts[i] >= self._max_violations:
            self._fail(i, f"stopped after {self._violation_counts[i]} violations (max_violations)")

    def destroy_node(self) -> None:
        self._inbox.destroy_node()
        super().destroy_node()
