"""Controller plugins that cannot be used, each in its own way (tests of the error messages)."""
from rclpy.node import Node


class ExplodesOnConstruct(Node):
    def __init__(self, **node_kwargs):
        super().__init__("explodes", **node_kwargs)
        raise ValueError("calibration file robot.cfg not found")


class NotANode:
    pass


class PublishesAnothersTopic(Node):
    def __init__(self, **node_kwargs):
        from geometry_msgs.msg import TwistStamped
        from sensor_msgs.msg import LaserScan
        super().__init__("intruder", **node_kwargs)
        self.create_subscription(LaserScan, "proximity", lambda scan: None, 10)
        self.create_publisher(TwistStamped, "/bot0/cmd_vel", 10)
