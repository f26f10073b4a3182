"""The simulator node: publishes each tick's sensors and /clock, collects the controllers' answers.

The node is the only ROS-facing piece of the simulator. It holds no simulation state: the host
hands it a SensorFrame to publish and reads back the commands as arrays.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
from rclpy.context import Context
from rclpy.node import Node
from rclpy.time import Time as RosTime
from rosgraph_msgs.msg import Clock

from composed_sim.core.robot_models import RobotModel
from composed_sim.core.simulation import SensorFrame
from composed_sim.ros import contract as c



@dataclass
class Violation:
    tick: int
    robot: str
    reason: str


def quiet_node_options() -> dict:
    """Thousands of nodes: no parameter services, no /rosout (each costs endpoints and discovery)."""
    return dict(start_parameter_services=False, enable_rosout=False)


class SimulatorNode(Node):
    """Sensor publishers and command subscriptions for every robot, in one node.

    Answers (``cmd_vel``) arrive through executor callbacks, possibly on worker threads; the
    host waits on ``wait_for_answers``. LED commands go to a separate inbox node that is never
    added to an executor and is drained by the host at the act phase, so an LED change
    published before a tick's answer always lands on the same tick, whatever the executor.
    """

    def __init__(self, names: list[str], models: list[RobotModel], *, context: Context,
                 tick_ns: int, node_name: str = "composed_sim"):
        super().__init__(node_name, context=context, **quiet_node_options())
        self._names = names
        self._models = models
        self._tick_ns = tick_ns
        n = len(names)
        self._inbox = Node(node_name + "_inbox", context=context, **quiet_node_options())
        self._clock_pub = self.create_publisher(Clock, c.CLOCK_TOPIC, 10)
        self._clock_msg = Clock()

        self._proximity_pubs, self._light_pubs, self._blob_pubs = [], [], []
        self._proximity_msgs, self._light_msgs, self._blob_msgs = [], [], []
        self._led_subs = []
        for i, (name, model) in enumerate(zip(names, models)):
            self._proximity_pubs.append(self.create_publisher(c.PROXIMITY.msg_type, c.topic_name(name, c.PROXIMITY), c.QOS))
            self._light_pubs.append(self.create_publisher(c.LIGHT.msg_type, c.topic_name(name, c.LIGHT), c.QOS))
            self._blob_pubs.append(self.create_publisher(c.BLOBS.msg_type, c.topic_name(name, c.BLOBS), c.QOS))
            self._proximity_msgs.append(c.ring_scan(model.proximity.angles_rad, name, model.proximity.range_m))
            self._light_msgs.append(c.ring_scan(model.light.angles_rad, name, 0.0))
            self._blob_msgs.append(c.blob_cloud(name))
            self.create_subscription(c.CMD_VEL.msg_type, c.topic_name(name, c.CMD_VEL),
                                     lambda msg, i=i: self._on_cmd_vel(i, msg), c.QOS)
            self._led_subs.append(self._inbox.create_subscription(
                c.LEDS.msg_type, c.topic_name(name, c.LEDS), lambda msg: None, c.QOS))

        # Answers to the current tick, written by callbacks (any thread), read by the host.
        self.linear = np.zeros(n)       # [n] m/s
        self.angular = np.zeros(n)      # [n] rad/s
        self.answered = np.zeros(n, dtype=bool)
        self._lock = threading.Lock()
        self._all_answered = threading.Event()
        self._n_answered = 0
        self._current_key = -1
        self._current_tick = -1
        self.violations: list[Violation] = []
        self._driven_clocks = []

    def drive_clock_of(self, node: Node) -> None:
        """Set a node's clock to sim time at each tick directly: a hosted node then sees sim time
        without its own /clock subscription (N deliveries per tick); /clock is still published."""
        clock = node.get_clock()
        clock._set_ros_time_is_active(True)
        self._driven_clocks.append(clock)

    # --- the tick exchange ----------------------------------------------------------------

    def publish_tick(self, frame: SensorFrame) -> None:
        """Publish /clock and every robot's sensors for ``frame.tick``; open the answer window."""
        stamp = c.stamp_of(frame.tick, self._tick_ns)
        with self._lock:
            self.answered[:] = False
            self._n_answered = 0
            self._all_answered.clear()
            self._current_key = c.stamp_key(stamp)
            self._current_tick = frame.tick
        self._clock_msg.clock = stamp
        self._clock_pub.publish(self._clock_msg)
        now = RosTime.from_msg(stamp)
        for clock in self._driven_clocks:
            clock.set_ros_time_override(now)
        blobs = frame.blobs
        points = c.blob_points(blobs.angles, blobs.distances, blobs.colors)
        for i in range(len(self._names)):
            msg = self._proximity_msgs[i]
            c.fill_proximity(msg, stamp, frame.proximity_distances[i], frame.proximity[i])
            self._proximity_pubs[i].publish(msg)
            msg = self._light_msgs[i]
            c.fill_light(msg, stamp, frame.light[i])
            self._light_pubs[i].publish(msg)
            lo, hi = blobs.offsets[i], blobs.offsets[i + 1]
            msg = self._blob_msgs[i]
            c.fill_blobs(msg, stamp, points[lo:hi])
            self._blob_pubs[i].publish(msg)

    def wait_for_answers(self, timeout_s: float) -> bool:
        return self._all_answered.wait(timeout_s)

    @property
    def all_answered(self) -> bool:
        return self._all_answered.is_set()

    def _on_cmd_vel(self, i: int, msg) -> None:
        key = c.stamp_key(msg.header.stamp)
        linear, angular = msg.twist.linear.x, msg.twist.angular.z
        with self._lock:
            if key != self._current_key:
                self._record(self._current_tick, i, f"answer stamped {key} ns is not for the current tick")
                return
            if self.answered[i]:
                return  # a second answer to the same tick: the first one counts
            if not (math.isfinite(linear) and math.isfinite(angular)):
                self._record(self._current_tick, i, "non-finite velocity command rejected")
            else:
                self.linear[i] = linear
                self.angular[i] = angular
            self.answered[i] = True
            self._n_answered += 1
            if self._n_answered == len(self._names):
                self._all_answered.set()

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """End the answer window: robots that did not answer get the fallback, recorded.

        Returns the (linear [n], angular [n]) commands to act on.
        """
        with self._lock:
            late = np.flatnonzero(~self.answered)
            self._current_key = -1   # later answers to this tick are stale
            linear, angular = self.linear.copy(), self.angular.copy()
            tick = self._current_tick
        for i in late:
            self._record(tick, i, "no answer before the watchdog")
            if fallback == "previous":
                linear[i], angular[i] = previous[0][i], previous[1][i]
            else:
                linear[i], angular[i] = 0.0, 0.0
        return linear, angular

    def take_led_commands(self) -> dict[int, np.ndarray]:
        """Drain the LED inbox: the latest valid colours per robot that sent any."""
        out = {}
        for i, sub in enumerate(self._led_subs):
            while True:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    break
                msg = taken[0]
                try:
                    out[i] = c.decode_leds(msg, self._models[i].n_leds)
                except ValueError as e:
                    self._record(self._current_tick, i, f"leds: {e}")
        return out

    def _record(self, tick: int, i: int, reason: str) -> None:
        self.violations.append(Violation(tick, self._names[i], reason))

    def destroy_node(self) -> None:
        self._inbox.destroy_node()
        super().destroy_node()
