"""Turns away from the nearest obstacle: the behaviour without the vote (for timing a chain)."""
import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from std_msgs.msg import Float32MultiArray


class Steer(Node):
    def __init__(self):
        super().__init__('steer')
        self.speed = self.declare_parameter('speed', 0.1).value
        self.turn_gain = self.declare_parameter('turn_gain', 1.0).value
        self.commands = self.create_publisher(Twist, 'cmd_out', 10)
        self.create_subscription(Float32MultiArray, 'ranges', self.on_ranges, 10)

    def on_ranges(self, msg):
        nearest, bearing = msg.data
        out = Twist()
        out.linear.x = self.speed
        out.angular.z = -self.turn_gain * bearing if nearest < 0.1 else 0.0
        self.commands.publish(out)


def main(args=None):
    rclpy.init(args=args)
    node = Steer()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
