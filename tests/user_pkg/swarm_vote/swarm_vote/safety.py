"""The last word before the wheels: caps the behaviour's speed."""
import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node


class Safety(Node):
    def __init__(self):
        super().__init__('safety')
        self.max_speed = self.declare_parameter('max_speed', 0.05).value
        # An absolute name built from the namespace, as many swarm packages write it.
        self.publisher = self.create_publisher(Twist, self.get_namespace() + '/cmd_vel', 10)
        self.create_subscription(Twist, 'drive_command', self.on_command, 10)

    def on_command(self, msg):
        msg.linear.x = max(-self.max_speed, min(self.max_speed, msg.linear.x))
        self.publisher.publish(msg)


def main(args=None):
    rclpy.init(args=args)
    node = Safety()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
