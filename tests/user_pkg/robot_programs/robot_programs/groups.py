"""A node whose callbacks share its default (mutually exclusive) callback group: one of them
sleeps on the node's clock across ticks, and a run-wide topic's messages, delivered meanwhile,
wait until it is done, as under rclpy's MultiThreadedExecutor."""
from geometry_msgs.msg import Twist
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Empty

from robot_programs.planning import twist
from robot_programs.steering import closeness, steer


class NapsInItsGroup(Node):
    """Steers on every scan (a reentrant group); every second its timer naps 0.35 s of sim time in
    the default group, which its run-wide ``/beat`` subscription shares."""

    def __init__(self):
        super().__init__("napper")
        self.napping = False
        self.naps = []              # (start, end) of each nap, s of sim time
        self.beats, self.beats_while_napping = 0, 0
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=ReentrantCallbackGroup())
        self.create_subscription(Empty, "/beat", self.on_beat, 10)
        self.create_timer(1.0, self.nap)

    def on_scan(self, scan):
        linear, angular = steer(closeness(scan))
        # Stops once a beat came while it napped: its paths tell, in a process of its own too.
        self.cmd.publish(twist(0.0 if self.beats_while_napping else linear, angular))

    def nap(self):
        self.napping = True
        start = self.get_clock().now().nanoseconds * 1e-9
        self.get_clock().sleep_for(Duration(seconds=0.35))
        self.naps.append((start, self.get_clock().now().nanoseconds * 1e-9))
        self.napping = False

    def on_beat(self, msg):
        self.beats += 1
        self.beats_while_napping += self.napping


class Drummer(Node):
    """Run-wide: publishes ``/beat`` every tick."""

    def __init__(self):
        super().__init__("drummer")
        self.beat = self.create_publisher(Empty, "/beat", 10)
        self.create_timer(0.1, lambda: self.beat.publish(Empty()))
