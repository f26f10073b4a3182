"""A movement pattern as many ROS 2 swarm packages write one: it keeps the latest ranges and
decides on a timer, publishing its drive command for the safety layer."""
import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from std_msgs.msg import Float32MultiArray


class TimedPattern(Node):
    def __init__(self):
        super().__init__('timed_pattern')
        self.speed = self.declare_parameter('speed', 0.1).value
        self.turn_gain = self.declare_parameter('turn_gain', 1.0).value
        self.latest = None
        self.commands = self.create_publisher(Twist, 'cmd_out', 10)
        self.create_subscription(Float32MultiArray, 'ranges', self.on_ranges, 10)
        self.timer = self.create_timer(0.1, self.on_timer)

    def on_ranges(self, msg):
        self.latest = msg.data

    def on_timer(self):
        out = Twist()
        if self.latest is not None:
            nearest, bearing = self.latest
            out.linear.x = self.speed
            out.angular.z = -self.turn_gain * bearing if nearest < 0.1 else 0.0
        self.commands.publish(out)


def main(args=None):
    rclpy.init(args=args)
    node = TimedPattern()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
