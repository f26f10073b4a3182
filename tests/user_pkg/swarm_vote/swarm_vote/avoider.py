"""The sensor layer, the steering and the safety cap in one node (for timing a chain against it)."""
import math

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class Avoider(Node):
    def __init__(self):
        super().__init__('avoider')
        self.speed = self.declare_parameter('speed', 0.1).value
        self.turn_gain = self.declare_parameter('turn_gain', 1.0).value
        self.max_speed = self.declare_parameter('max_speed', 0.05).value
        self.range_max = self.declare_parameter('range_max', 0.1).value
        self.publisher = self.create_publisher(Twist, 'cmd_vel', 10)
        self.create_subscription(LaserScan, 'scan', self.on_scan, 10)

    def on_scan(self, scan):
        best, bearing = self.range_max, 0.0
        for i, r in enumerate(scan.ranges):
            if math.isfinite(r) and r < best:
                best, bearing = r, scan.angle_min + i * scan.angle_increment
        out = Twist()
        out.linear.x = min(self.speed, self.max_speed)
        out.angular.z = -self.turn_gain * bearing if best < 0.1 else 0.0
        self.publisher.publish(out)


def main(args=None):
    rclpy.init(args=args)
    node = Avoider()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
