"""What every program here drives by: forward, slower near an obstacle, turning once it is close."""
from geometry_msgs.msg import Twist
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


def closeness(scan) -> float:
    """How close the nearest obstacle is, from a proximity ring's scan (0: none, 1: touching)."""
    return max(scan.intensities) if len(scan.intensities) else 0.0


def twist(linear: float, angular: float = 0.0) -> Twist:
    out = Twist()
    out.linear.x, out.angular.z = linear, angular
    return out


class Drive(Node):
    """The robot's base driver: a command for every scan, so that the robot answers each tick
    while its other nodes do what the test is about."""

    def __init__(self):
        super().__init__("drive")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan):
        close = closeness(scan)
        self.cmd.publish(twist(0.05 * (1.0 - close), 1.0 if close > 0.3 else 0.0))
