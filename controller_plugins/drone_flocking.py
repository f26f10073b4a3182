"""3D flocking of Crazyflies with range and bearing: each drone climbs to its cruise altitude, keeps
its neighbours at a target distance in three dimensions (the generalised Lennard-Jones potential of
the paper's flocking, over range, bearing and elevation) and drifts with the flock towards a goal,
streaming its position setpoint on ``cmd_position`` every tick, as a Crazyswarm2 script streams one.

A plain rclpy node of the robot's namespace: it reads ``rab_rx`` (the neighbours heard, decoded with
composed_sim.devices.range_and_bearing) and ``pose`` (where it is), and publishes
crazyflie_interfaces/Position (a package the user builds from Crazyswarm2's source,
docs/crazyflie.md). Its setpoint moves at most ``max_speed_mps``: the firmware flies to it
exactly (Crazyswarm2's ``none`` backend), so a step is never larger than a real drone could make.
"""
from __future__ import annotations

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from composed_sim.devices import range_and_bearing


class DroneFlocking(Node):
    def __init__(self):
        super().__init__("drone_flocking")
        try:
            from crazyflie_interfaces.msg import Position
        except ImportError as e:
            raise ImportError("drone-flocking publishes crazyflie_interfaces/Position: build Crazyswarm2's "
                              "crazyflie_interfaces (docs/crazyflie.md)") from e
        p = {name: self.declare_parameter(name, value).value for name, value in (
            ("target_distance_m", 0.8), ("gain", 0.6), ("max_speed_mps", 0.4), ("altitude_m", 1.0),
            ("altitude_gain", 0.8), ("climb_mps", 0.4), ("goal", [3.0, 0.0]), ("goal_speed_mps", 0.15))}
        self._distance, self._gain, self._max_speed = p["target_distance_m"], p["gain"], p["max_speed_mps"]
        self._altitude, self._altitude_gain, self._climb = p["altitude_m"], p["altitude_gain"], p["climb_mps"]
        self._goal, self._goal_speed = np.array(p["goal"], dtype=float), p["goal_speed_mps"]
        self._neighbours = np.zeros((0, 3))              # relative positions of those heard this tick
        self._setpoint = None                            # [3] m, where the drone is asked to be
        self._cruising = False                           # climbed to half its altitude once
        self._last_ns = None
        self.create_subscription(PointCloud2, "rab_rx", self._heard, 10, raw=True)
        self.create_subscription(PoseStamped, "pose", self._at, 10)
        self._msg = Position()
        self._out = self.create_publisher(Position, "cmd_position", 10)

    def _heard(self, data: bytes) -> None:
        heard = range_and_bearing.decode(data)
        flat = heard.ranges * np.cos(heard.elevations)
        self._neighbours = np.column_stack([flat * np.cos(heard.bearings), flat * np.sin(heard.bearings),
                                            heard.ranges * np.sin(heard.elevations)])

    def _at(self, pose: PoseStamped) -> None:
        now = pose.header.stamp.sec * 1_000_000_000 + pose.header.stamp.nanosec
        here = np.array([pose.pose.position.x, pose.pose.position.y, pose.pose.position.z])
        if self._setpoint is None:
            self._setpoint = here.copy()
        dt = 0.0 if self._last_ns is None else (now - self._last_ns) * 1e-9
        self._last_ns = now
        self._setpoint += self._velocity(here) * dt
        msg = self._msg
        msg.header.stamp = pose.header.stamp
        msg.x, msg.y, msg.z, msg.yaw = (float(v) for v in (*self._setpoint, 0.0))
        self._out.publish(msg)

    def _velocity(self, here: np.ndarray) -> np.ndarray:
        """Climb first; then the flock's pull and push, the altitude's spring and the goal's drift."""
        self._cruising = self._cruising or here[2] >= 0.5 * self._altitude
        if not self._cruising:
            return np.array([0.0, 0.0, self._climb])
        v = np.zeros(3)
        if len(self._neighbours):
            d = np.linalg.norm(self._neighbours, axis=1)
            x = (self._distance / np.maximum(d, 1e-3)) ** 2
            # Lennard-Jones: positive (away) closer than the target distance, negative (towards) beyond.
            v -= self._gain * ((x * x - x)[:, None] * self._neighbours / np.maximum(d, 1e-3)[:, None]).sum(axis=0)
        v[2] += self._altitude_gain * (self._altitude - here[2])
        to_goal = self._goal - here[:2]
        distance = np.linalg.norm(to_goal)
        if distance > 0.05:
            v[:2] += self._goal_speed * to_goal / distance
        speed = np.linalg.norm(v)
        return v if speed <= self._max_speed else v * (self._max_speed / speed)
