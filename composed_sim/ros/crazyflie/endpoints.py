"""A block of drones' Crazyswarm2 endpoints, beside its simulator node (as their sensors and
cmd_vel are): what a script or a hosted node calls and publishes for ``/<cf>/…``.

- **services** (``/<cf>/takeoff``, ``land``, ``go_to``, ``upload_trajectory``, ``start_trajectory``,
  ``notify_setpoints_stop``, ``emergency``, ``arm``): each answers at once (their responses are
  empty, as Crazyswarm2's are) and posts what it asks to the process's outbox. The host serves them
  in process (``services()``, hosting/drones.py): a hosted node's call is served in the walk, a
  run-wide node's in the rounds between places, another process's at the tick's start. A drone's
  ``start_trajectory`` is on the ROS graph from the start (``crazyflie_py`` finds the drones by
  it); the others get their DDS endpoints once a client in another process looks for them.
- **setpoint topics** (``cmd_full_state``, ``cmd_position``, ``cmd_hover``, ``cmd_velocity_world``,
  ``cmd_vel_legacy``): subscribed once another node publishes one (``refresh``, when the graph
  changed), on a node no executor spins, and taken at the tick's close (``drain``), stamped with
  when they were published: a drone nobody streams to costs nothing per tick.
- **status** (crazyflie_interfaces/Status): published once a second of sim time, as Crazyswarm2's
  default logging does, to whoever subscribed (a publisher is made once someone does).

The ``pose`` topic is the positioning device's (``/<cf>/pose``, every tick, in the world frame).
"""
from __future__ import annotations

import functools
import time
from typing import Callable, Optional, Sequence

from builtin_interfaces.msg import Time
from rclpy.context import Context
from rclpy.node import Node

from composed_sim.ros.crazyflie import messages
from composed_sim.ros.crazyflie.messages import Interfaces
from composed_sim.ros.crazyflie.outbox import DroneOutbox
from composed_sim.ros.robot_settings import quiet_node_options
from composed_sim.ros.topic import QOS
from composed_sim.world.crazyflies import Crazyflie

ON_THE_GRAPH = "start_trajectory"       # the service a script finds the drones by
PM_STATE_BATTERY = 0                    # Status.pm_state: on battery


class ServiceSpec:
    """One drone service for the host to serve: its resolved name, type, callback (rclpy's
    ``callback(request, response)``), whether it is on the ROS graph from the start, and its
    drone's robot index."""
    __slots__ = ("name", "srv_type", "callback", "on_graph", "robot")

    def __init__(self, name: str, srv_type: type, callback: Callable, on_graph: bool, robot: int):
        self.name, self.srv_type, self.callback, self.on_graph, self.robot = name, srv_type, callback, on_graph, robot


class DroneEndpoints:
    def __init__(self, context: Context, drones: Sequence[Crazyflie], interfaces: Interfaces, outbox: DroneOutbox,
                 *, node_name: str, tick_ns: int, battery_v: float, frame_start: int = 0):
        """``drones``: this block's, in robot order; ``outbox``: where their commands go;
        ``frame_start``: the robot of the first row of the frames this block reads."""
        self.drones = list(drones)
        self._frame_start = frame_start
        self._interfaces, self._outbox = interfaces, outbox
        self._tick_ns, self._battery_v = tick_ns, battery_v
        self._status_every = max(1, round(messages.STATUS_PERIOD_S * 1e9 / tick_ns))
        # The services' node, in the block's executor (its services are served by the walk).
        self.node = Node(node_name, context=context, **quiet_node_options())
        # The setpoint subscriptions and status publishers: no executor spins them.
        self.inbox = Node(node_name + "_inbox", context=context, **quiet_node_options())
        self._subscribed: set[str] = set()
        self._setpoints: list[tuple[int, Callable, object]] = []    # (robot, convert, subscription)
        self._taken: dict[str, int] = {}     # setpoints taken since the start, by topic (``drain``)
        self._status: list[tuple[int, object]] = []                  # (row, publisher)
        self._watched = {f"/{d.name}/{topic}": (row, topic) for row, d in enumerate(self.drones)
                         for topic in (*messages.SETPOINTS, messages.STATUS)}
        self._status_msg = interfaces.status()

    def services(self) -> list[ServiceSpec]:
        """Every drone's services, drone by drone, for the host to serve."""
        specs = []
        for drone in self.drones:
            for name, (_, _, convert) in messages.SERVICES.items():
                callback = functools.partial(self._served, drone.robot, convert)
                specs.append(ServiceSpec(f"/{drone.name}/{name}", self._interfaces.services[name], callback,
                                         name == ON_THE_GRAPH, drone.robot))
        return specs

    def _served(self, robot: int, convert: Callable, request, response):
        kind, args = convert(request)
        self._outbox.post(robot, kind, args)
        return response

    # --- setpoint topics and status, made as the graph asks for them -------------------------------

    def refresh(self) -> int:
        """The ROS graph changed: subscribe to the setpoint topics another node now publishes, and
        publish the status topics another node now reads. How many endpoints were made."""
        made = 0
        for topic, _ in self.inbox.get_topic_names_and_types():
            found = self._watched.get(topic)
            if found is None or topic in self._subscribed:
                continue
            row, name = found
            drone = self.drones[row]
            if name == messages.STATUS:
                if self.inbox.count_subscribers(topic) < 1:
                    continue
                self._status.append((row, self.inbox.create_publisher(self._interfaces.status, topic, QOS)))
            else:
                if self.inbox.count_publishers(topic) < 1:
                    continue
                subscription = self.inbox.create_subscription(self._interfaces.setpoints[name], topic,
                                                              lambda msg: None, QOS)
                self._setpoints.append((drone.robot, messages.SETPOINTS[name][2], subscription))
            self._subscribed.add(topic)
            made += 1
        if made:
            self._setpoints.sort(key=lambda s: s[0])
        return made

    def endpoints_by_topic(self) -> dict:
        """The setpoint subscriptions made so far, by topic (for a host's matching checks)."""
        return {subscription.topic_name: subscription for _, _, subscription in self._setpoints}

    def drain(self, sent: Optional[dict[str, int]] = None, timeout_s: float = 1.0) -> int:
        """The setpoints received since the last drain, to the outbox, each stamped with when it
        was published (its order among its drone's calls); how many. ``sent``: how many a topic's
        publishers said they sent since the start (a drone's controller in a process of its own):
        those not taken yet are waited for, up to ``timeout_s`` (what DDS still carries belongs to
        the tick). Counted since the start, not per tick: a setpoint published after its
        process's part of a tick went out is counted with its next part, and may be taken first."""
        taken, deadline = 0, time.monotonic() + timeout_s
        for robot, convert, subscription in self._setpoints:
            handle, msg_type, topic = subscription.handle, subscription.msg_type, subscription.topic_name
            owed = (sent.get(topic, 0) if sent else 0) - self._taken.get(topic, 0)
            while True:
                with handle:
                    got = handle.take_message(msg_type, False)
                if got is None:
                    if owed <= 0 or time.monotonic() > deadline:
                        break
                    time.sleep(0.0001)
                    continue
                kind, args = convert(got[0])
                self._outbox.post(robot, kind, args, got[1]["source_timestamp"])
                taken, owed = taken + 1, owed - 1
                self._taken[topic] = self._taken.get(topic, 0) + 1
        return taken

    def publish_status(self, tick: int, supervisor_info: Optional[Sequence[int]]) -> None:
        """Each read status topic, once a second of sim time; ``supervisor_info``: the frame's
        robots' bits (core/senses.py)."""
        if not self._status or tick % self._status_every or supervisor_info is None:
            return
        msg = self._status_msg
        ns = tick * self._tick_ns
        msg.header.stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
        msg.battery_voltage = self._battery_v
        msg.pm_state = PM_STATE_BATTERY
        for row, publisher in self._status:
            msg.header.frame_id = self.drones[row].name
            msg.supervisor_info = int(supervisor_info[self.drones[row].robot - self._frame_start])
            publisher.publish(msg)

    def destroy(self) -> None:
        self.inbox.destroy_node()
        self.node.destroy_node()
