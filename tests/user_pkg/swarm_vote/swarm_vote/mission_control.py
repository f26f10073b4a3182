"""Starts the swarm at a given time (and may stop it), on the run-wide /swarm_command."""
import rclpy
from rclpy.node import Node
from std_msgs.msg import String


class MissionControl(Node):
    def __init__(self):
        super().__init__('mission_control')
        self.start_s = self.declare_parameter('start_s', 0.0).value
        self.publisher = self.create_publisher(String, '/swarm_command', 10)
        self.sent = False
        self.timer = self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        if not self.sent and self.get_clock().now().nanoseconds >= self.start_s * 1e9:
            self.publisher.publish(String(data='start'))
            self.sent = True


def main(args=None):
    rclpy.init(args=args)
    node = MissionControl()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
