"""A third-party controller written as a plain rclpy Node, with no composed_sim import at all:
it reads the proximity ring and drives forward, turning away from whatever is close."""
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class PlainForward(Node):
    def __init__(self, **node_kwargs):
        super().__init__("plain_forward", **node_kwargs)
        self.speed = self.declare_parameter("speed", 0.05).value
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_proximity, 10)

    def on_proximity(self, scan: LaserScan) -> None:
        answer = TwistStamped()
        answer.header.stamp = scan.header.stamp      # the lockstep answer carries the tick's stamp
        close = max(scan.intensities) if len(scan.intensities) else 0.0
        answer.twist.linear.x = self.speed * (1.0 - close)
        answer.twist.angular.z = 1.0 if close > 0.3 else 0.0
        self.cmd.publish(answer)
