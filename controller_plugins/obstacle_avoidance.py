"""A TurtleBot 3 node written the way ROS users write one, and nothing else: no composed_sim
import, no stamps, no lockstep awareness.

- it subscribes to ``scan`` with ``qos_profile_sensor_data`` (best effort) and keeps the latest
  reading in the callback;
- it decides on a 10 Hz ``create_timer``;
- it publishes ``geometry_msgs/Twist`` on ``cmd_vel``;
- stop and turn: it drives straight on while the sector ahead is clear, and otherwise stops and
  turns on the spot towards the side with more room, until the way ahead is clear again.

The same file runs unchanged on a real burger or in Gazebo; here the host runs it on sim time,
and its timer fires once per tick after the tick's scan arrived (docs/contract.md).
"""
from __future__ import annotations

import math

from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan


class ObstacleAvoidance(Node):
    def __init__(self, **kwargs):
        super().__init__("obstacle_avoidance", **kwargs)
        self.speed = self.declare_parameter("speed_mps", 0.15).value
        self.turn_speed = self.declare_parameter("turn_speed_radps", 1.2).value
        self.stop_distance = self.declare_parameter("stop_distance_m", 0.35).value
        self.front_half_angle = math.radians(self.declare_parameter("front_half_angle_deg", 30.0).value)
        period = self.declare_parameter("period_s", 0.1).value
        self.scan: LaserScan | None = None
        self.turning = 0.0                      # the turn under way (rad/s), 0 while driving
        self.cmd_pub = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "scan", self.on_scan, qos_profile_sensor_data)
        self.create_timer(period, self.decide)

    def on_scan(self, msg: LaserScan) -> None:
        self.scan = msg

    def decide(self) -> None:
        if self.scan is None:
            return
        ahead, left, right = self.sectors(self.scan)
        cmd = Twist()
        if ahead > self.stop_distance:
            self.turning = 0.0
            cmd.linear.x = self.speed
        else:
            if self.turning == 0.0:             # keep one direction until clear: no dithering
                self.turning = self.turn_speed if left >= right else -self.turn_speed
            cmd.angular.z = self.turning
        self.cmd_pub.publish(cmd)

    def sectors(self, scan: LaserScan) -> tuple[float, float, float]:
        """The nearest obstacle ahead (within ±front_half_angle), and the mean free range on the
        left and on the right half (m). Rays with nothing in range count as range_max."""
        ahead, left, right = math.inf, [], []
        for i, r in enumerate(scan.ranges):
            angle = math.remainder(scan.angle_min + i * scan.angle_increment, math.tau)
            free = scan.range_max if math.isinf(r) and r > 0 else r
            if math.isnan(free) or free < 0:
                free = 0.0                      # -inf: closer than range_min
            if abs(angle) <= self.front_half_angle:
                ahead = min(ahead, free)
            (left if angle > 0 else right).append(free)
        return ahead, sum(left) / max(len(left), 1), sum(right) / max(len(right), 1)
