"""Lifecycle nodes: the publisher and subscription made in ``on_configure``, commands only while
active; started by the world file (autostart), by the node itself, or by a lifecycle manager."""
from geometry_msgs.msg import Twist
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from robot_programs.planning import twist
from robot_programs.steering import closeness, steer


class LifecycleBehaviour(LifecycleNode):
    """Steers from its proximity ring once configured and active."""

    def __init__(self, name: str = "behaviour"):
        super().__init__(name)
        self.cmd_topic = self.declare_parameter("cmd_topic", "cmd_vel").value
        self.cmd = None
        self.transitions = []

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.transitions.append("configure")
        self.cmd = self.create_lifecycle_publisher(Twist, self.cmd_topic, 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.transitions.append("activate")
        return super().on_activate(state)

    def on_scan(self, scan):
        if self.cmd is not None:        # a lifecycle publisher drops what it gets while inactive
            self.cmd.publish(twist(*steer(closeness(scan))))


class SelfStartingBehaviour(LifecycleBehaviour):
    """Configures and activates itself at the end of its constructor."""

    def __init__(self):
        super().__init__()
        self.trigger_configure()
        self.trigger_activate()


class LifecycleManager(Node):
    """A run-wide node that brings every robot's ``behaviour`` up through its lifecycle services
    (``change_state``: configure, then activate), as nav2's lifecycle manager does at start-up."""

    def __init__(self):
        super().__init__("lifecycle_manager")
        robots = self.declare_parameter("robots", ["bot0"]).value
        group = ReentrantCallbackGroup()
        self.clients_ = [self.create_client(ChangeState, f"/{r}/behaviour/change_state", callback_group=group)
                         for r in robots]
        self.results = []
        self.started = False
        self.create_timer(0.1, self.start, callback_group=group)

    def start(self):
        if self.started:
            return
        self.started = True
        for client in self.clients_:
            self.change(client, Transition.TRANSITION_CONFIGURE, then=Transition.TRANSITION_ACTIVATE)

    def change(self, client, transition: int, then: int = None):
        request = ChangeState.Request()
        request.transition.id = transition
        future = client.call_async(request)
        future.add_done_callback(lambda f: self.changed(client, f, then))

    def changed(self, client, future, then):
        self.results.append(future.result().success)
        if then is not None:
            self.change(client, then)
