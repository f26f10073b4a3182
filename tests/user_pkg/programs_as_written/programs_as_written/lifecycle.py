"""Lifecycle nodes as users write them: one that configures and activates itself from a timer
(as it would under a lifecycle manager that starts it later), and a talker driven through
configure, activate, deactivate and clean-up, whose ``on_cleanup`` destroys its timer."""
from geometry_msgs.msg import Twist
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String

from programs_as_written.driving import closeness, twist


class SteeringLifecycleNode(LifecycleNode):
    """Makes its ``cmd_vel`` lifecycle publisher in ``on_configure``; says when it is configured
    and activated."""

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.cmd = self.create_lifecycle_publisher(Twist, "cmd_vel", 10)
        self.get_logger().info("configured")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("activated")
        return super().on_activate(state)


class LateActivating(SteeringLifecycleNode):
    """Makes its ``cmd_vel`` lifecycle publisher in ``on_configure``; configures and activates
    itself from a 0.3 s timer; steers from every scan once active."""

    def __init__(self):
        super().__init__("behaviour")
        self.cmd = None
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.starter = self.create_timer(0.3, self.start)

    def start(self):
        self.starter.cancel()
        self.trigger_configure()
        self.trigger_activate()

    def on_scan(self, scan):
        if self.cmd is not None and self.cmd.is_activated:
            self.cmd.publish(twist(0.05 * (1.0 - closeness(scan))))


class EagerSteerer(SteeringLifecycleNode):
    """Configures itself at 0.2 s and activates at 0.5 s (a manager's sequence, from a timer of its
    own); its 0.1 s control timer publishes on the lifecycle ``cmd_vel`` publisher from the
    configure on, without asking whether it is active: until then rclpy's lifecycle publisher
    drops what it is given."""

    def __init__(self):
        super().__init__("steerer")
        self.cmd = None
        self.ticks = 0
        self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        self.ticks += 1
        if self.ticks == 2:
            self.trigger_configure()
        elif self.ticks == 5:
            self.trigger_activate()
        if self.cmd is not None:
            self.cmd.publish(twist(0.05))


class CleanedUpTalker(LifecycleNode):
    """lifecycle_py's talker pattern: a timer and a publisher made in ``on_configure``, published
    on while active, destroyed in ``on_cleanup``. This one steps itself through configure (0.2 s),
    activate (0.4 s), deactivate (0.7 s) and clean-up (0.9 s) from a timer of its own."""

    STEPS = {2: "configure", 4: "activate", 7: "deactivate", 9: "cleanup"}

    def __init__(self):
        super().__init__("talker")
        self.count = 0
        self.ticks = 0
        self.pub = self.timer = None
        self.create_timer(0.1, self.step)

    def step(self):
        self.ticks += 1
        transition = self.STEPS.get(self.ticks)
        if transition is not None:
            getattr(self, f"trigger_{transition}")()

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(String, "chatter", 10)
        self.timer = self.create_timer(0.1, self.publish)
        self.get_logger().info("on_configure() is called.")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("on_activate() is called.")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("on_deactivate() is called.")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        self.destroy_timer(self.timer)
        self.destroy_publisher(self.pub)
        self.timer = self.pub = None
        self.get_logger().info("on_cleanup() is called.")
        return TransitionCallbackReturn.SUCCESS

    def publish(self):
        self.count += 1
        if self.pub is not None and self.pub.is_activated:
            self.get_logger().info(f"Lifecycle publisher is active. Publishing: [Lifecycle HelloWorld #{self.count}]")
            self.pub.publish(String(data=f"Lifecycle HelloWorld #{self.count}"))
