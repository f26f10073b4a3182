"""A test controller that logs: every robot drives a circle, logs each scan at INFO (and, with
``child``, through a child logger), warns once per scan from ``warn_from`` on, and the robots of
``raise_robots`` divide by zero two frames below their callback at ``raise_at`` (their
``raise_at``-th scan). A plain rclpy Node, like any third party's."""
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


def ratio(a: float, b: float) -> float:
    return a / b                                   # RAISES HERE


def steer(scans: int, raise_at: int) -> float:
    return ratio(1.0, float(raise_at - scans))


class Chatty(Node):
    def __init__(self):
        super().__init__("chatty")
        self.log_every_scan = self.declare_parameter("log_every_scan", True).value
        self.warn_from = self.declare_parameter("warn_from", -1).value
        self.raise_robots = self.declare_parameter("raise_robots", "").value.split(",")
        self.raise_at = self.declare_parameter("raise_at", -1).value
        self.child = self.declare_parameter("child", False).value
        self.me = self.get_namespace().strip("/")
        self.scans = 0
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.get_logger().info(f"{self.me} ready")

    def on_scan(self, scan: LaserScan) -> None:
        scans, self.scans = self.scans, self.scans + 1
        if self.log_every_scan:
            self.get_logger().info(f"scan {scans} of {self.me}")
        if self.child:
            self.get_logger().get_child("planner").debug(f"planning {scans}")
            self.get_logger().get_child("planner").info(f"planned {scans}")
        if 0 <= self.warn_from <= scans:
            self.get_logger().warn(f"battery low on {self.me}")
        answer = TwistStamped()
        answer.header.stamp = scan.header.stamp
        answer.twist.linear.x = 0.05
        if self.me in self.raise_robots:
            answer.twist.angular.z = steer(scans, self.raise_at)
        self.cmd.publish(answer)
