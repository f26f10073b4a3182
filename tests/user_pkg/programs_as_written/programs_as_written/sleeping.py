"""A node whose scan callback pauses now and then (``time.sleep``, in a group of its own) while
its 10 Hz control timer keeps steering: the way a user's node waits for a slow sensor to settle."""
import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from geometry_msgs.msg import Twist

from programs_as_written.driving import closeness, twist


class PausingScanner(Node):
    """Its scan callback, in a group of its own, pauses 0.3 s on the scan of 0.1 s; its timer
    (the node's default group) steers every 0.1 s from the last scan it has."""

    def __init__(self):
        super().__init__("scanner")
        self.close = 0.0
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self.create_timer(0.1, self.on_timer)

    def now_s(self) -> float:
        return round(self.get_clock().now().nanoseconds * 1e-9, 3)

    def on_scan(self, scan):
        self.close = closeness(scan)
        stamp = scan.header.stamp.sec + scan.header.stamp.nanosec * 1e-9
        if round(stamp, 3) == 0.1:
            self.get_logger().info(f"pausing at {self.now_s():g} s")
            time.sleep(0.3)
            self.get_logger().info(f"resumed at {self.now_s():g} s")

    def on_timer(self):
        self.get_logger().info(f"steer at {self.now_s():g} s")
        self.cmd.publish(twist(0.05 * (1.0 - self.close)))
