"""Turns the robot's range scan into the ranges the behaviour reads."""
import math

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float32MultiArray


class SensorLayer(Node):
    def __init__(self):
        super().__init__('sensor_layer')
        self.range_max = self.declare_parameter('range_max', 0.1).value
        self.publisher = self.create_publisher(Float32MultiArray, 'ranges', 10)
        self.subscription = self.create_subscription(LaserScan, 'scan', self.on_scan, 10)

    def on_scan(self, scan):
        msg = Float32MultiArray()
        # [nearest range, its bearing]
        best, bearing = self.range_max, 0.0
        for i, r in enumerate(scan.ranges):
            if math.isfinite(r) and r < best:
                best, bearing = r, scan.angle_min + i * scan.angle_increment
        msg.data = [float(best), float(bearing)]
        self.publisher.publish(msg)


def main(args=None):
    rclpy.init(args=args)
    node = SensorLayer()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
