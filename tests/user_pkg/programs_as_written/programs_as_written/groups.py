"""A callback group of the user's own: ``can_execute`` lets a callback run at most once per half
second of the node's clock, so a 10 Hz timer in it runs twice a second."""
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from std_msgs.msg import String


class HalfSecondGroup(CallbackGroup):
    """Lets one callback begin per ``period`` of ``clock``; the others wait until it has passed."""

    def __init__(self, clock, period_s: float = 0.5):
        super().__init__()
        self.clock = clock
        self.period_ns = int(period_s * 1e9)
        self.last_ns = None

    def can_execute(self, entity) -> bool:
        now = self.clock.now().nanoseconds
        return self.last_ns is None or now - self.last_ns >= self.period_ns

    def beginning_execution(self, entity) -> bool:
        if not self.can_execute(entity):
            return False
        self.last_ns = self.clock.now().nanoseconds
        return True

    def ending_execution(self, entity) -> None:
        pass


class ThrottledChatter(Node):
    """A 10 Hz timer in a ``HalfSecondGroup``: publishes and logs twice a second."""

    def __init__(self):
        super().__init__("chatter")
        self.count = 0
        self.pub = self.create_publisher(String, "chatter", 10)
        self.create_timer(0.1, self.speak, callback_group=HalfSecondGroup(self.get_clock()))

    def speak(self):
        self.count += 1
        self.get_logger().info(f"Publishing: {self.count}")
        self.pub.publish(String(data=f"Hello {self.count}"))
