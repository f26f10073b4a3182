"""The swarm behaviour: waits for the start command, shares its opinion with every robot on
/opinions, takes the majority of what it heard, and drives while it hears the whole swarm."""
import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from std_msgs.msg import Float32MultiArray, String
from swarm_vote_interfaces.msg import Opinion


class Behaviour(Node):
    def __init__(self):
        super().__init__('behaviour')
        self.speed = self.declare_parameter('speed', 0.1).value
        self.swarm_size = self.declare_parameter('swarm_size', 1).value
        self.turn_gain = self.declare_parameter('turn_gain', 1.0).value
        self.me = self.get_namespace().strip('/')
        self.opinion = 1 if int(''.join(c for c in self.me if c.isdigit()) or 0) % 3 == 0 else 0
        self.started = False
        self.heard = {}          # sender -> (tick stamp ns, opinion)
        self.commands = self.create_publisher(Twist, 'cmd_out', 10)
        self.opinions = self.create_publisher(Opinion, '/opinions', 10)
        self.create_subscription(String, '/swarm_command', self.on_command, 10)
        self.create_subscription(Opinion, '/opinions', self.on_opinion, 100)
        self.create_subscription(Float32MultiArray, 'ranges', self.on_ranges, 10)

    def on_command(self, msg):
        self.started = msg.data == 'start'

    def on_opinion(self, msg):
        self.heard[msg.sender] = (msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec, msg.opinion)

    def on_ranges(self, msg):
        clock_now = self.get_clock().now()
        now = clock_now.nanoseconds
        period = 100_000_000
        heard_all = sum(1 for stamp, _ in self.heard.values() if stamp == now - period) == self.swarm_size
        if heard_all:
            votes = [o for _, o in self.heard.values()]
            self.opinion = 1 if 2 * sum(votes) > len(votes) else 0
        out = Twist()
        if self.started and (now == 0 or heard_all):
            nearest, bearing = msg.data
            out.linear.x = self.speed
            out.angular.z = -self.turn_gain * bearing if nearest < 0.1 else 0.0
        self.commands.publish(out)
        self.opinions.publish(Opinion(sender=self.me, opinion=self.opinion, stamp=clock_now.to_msg()))


def main(args=None):
    rclpy.init(args=args)
    node = Behaviour()
    rclpy.spin(node)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
