"""Controllers written the ways ROS users write nodes, with no composed_sim import: unstamped
Twist, timer-driven decisions, sensor-data QoS. They all steer alike (drive on, turn away from
what is close), so runs that mix them can be compared bit for bit across hosts and executors."""
from geometry_msgs.msg import Twist, TwistStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String


def steer(scan: LaserScan) -> tuple[float, float]:
    close = max(scan.intensities) if len(scan.intensities) else 0.0
    return 0.05 * (1.0 - close), (1.0 if close > 0.3 else 0.0)


class TwistOnScan(Node):
    """Decides in its sensor callback (best effort, as sensor data usually is), publishes Twist."""

    def __init__(self, **kwargs):
        super().__init__("twist_on_scan", **kwargs)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, qos_profile_sensor_data)
        self.readings = 0

    def on_scan(self, scan: LaserScan) -> None:
        self.readings += 1
        out = Twist()
        out.linear.x, out.angular.z = steer(scan)
        self.cmd.publish(out)


class _OnTimer(Node):
    """Keeps the latest reading; decides on a timer (``period`` s)."""
    msg_type, qos = Twist, qos_profile_sensor_data

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        period = self.declare_parameter("period", 0.1).value
        self.cmd = self.create_publisher(self.msg_type, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, self.qos)
        self.scan = None
        self.decisions = 0
        self.create_timer(period, self.decide)

    def on_scan(self, scan: LaserScan) -> None:
        self.scan = scan

    def decide(self) -> None:
        if self.scan is None:
            return
        self.decisions += 1
        self.cmd.publish(self.command(*steer(self.scan)))


class StampedTimer(_OnTimer):
    """TwistStamped stamped with its own clock, reliable subscription."""
    msg_type, qos = TwistStamped, 10

    def __init__(self, **kwargs):
        super().__init__("stamped_timer", **kwargs)

    def command(self, linear: float, angular: float) -> TwistStamped:
        out = TwistStamped()
        out.header.stamp = self.get_clock().now().to_msg()
        out.twist.linear.x, out.twist.angular.z = linear, angular
        return out


class UnstampedTimer(_OnTimer):
    """TwistStamped with its header left as made (stamp zero), as a node written for a robot whose
    base ignores the stamp publishes it."""
    msg_type = TwistStamped

    def __init__(self, **kwargs):
        super().__init__("unstamped_timer", **kwargs)

    def command(self, linear: float, angular: float) -> TwistStamped:
        out = TwistStamped()
        out.twist.linear.x, out.twist.angular.z = linear, angular
        return out


class TwistTimer(_OnTimer):
    """The usual ROS node: sensor-data QoS, latest reading kept, Twist from a timer."""

    def __init__(self, **kwargs):
        super().__init__("twist_timer", **kwargs)

    def command(self, linear: float, angular: float) -> Twist:
        out = Twist()
        out.linear.x, out.angular.z = linear, angular
        return out


class NoOptions(Node):
    """Written as the ROS 2 tutorials write a node: no node options taken, relative topic names."""

    def __init__(self):
        super().__init__("no_options")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan: LaserScan) -> None:
        out = Twist()
        out.linear.x, out.angular.z = steer(scan)
        self.cmd.publish(out)


class WrongSensor(Node):
    """Subscribes to a sensor its robot does not have."""

    def __init__(self):
        super().__init__("wrong_sensor")
        self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", lambda scan: None, 10)


class NoAnswer(Node):
    """Publishes its commands on a topic other than its robot's cmd_vel."""

    def __init__(self):
        super().__init__("no_answer")
        self.create_publisher(Twist, "cmd_vel_out", 10)
        self.create_subscription(LaserScan, "proximity", lambda scan: None, 10)


class StringCommands(Node):
    """Publishes the wrong type on cmd_vel."""

    def __init__(self, **kwargs):
        super().__init__("string_commands", **kwargs)
        self.create_publisher(String, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", lambda scan: None, 10)


class EveryThirdTick(Node):
    """Publishes cmd_vel only on every third tick, as software that sends a command when it
    decides to: its robot group says ``answers: when_published``."""

    def __init__(self):
        super().__init__("every_third_tick")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan: LaserScan) -> None:
        tick = round(self.get_clock().now().nanoseconds / 1e8)
        if tick % 3 == 0:
            out = Twist()
            out.linear.x, out.angular.z = 0.05, 0.3 * ((tick // 3) % 2 * 2 - 1)
            self.cmd.publish(out)


class AsksThePlanner(Node):
    """Asks its robot's planner (a service of another node of the robot) on each scan, and drives
    as the response says: a client and a service between a robot's own nodes."""

    def __init__(self):
        super().__init__("asks_the_planner")
        from std_srvs.srv import Trigger
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.client = self.create_client(Trigger, "plan")
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.request = Trigger.Request()

    def on_scan(self, scan: LaserScan) -> None:
        self.client.call_async(self.request).add_done_callback(self.on_plan)

    def on_plan(self, future) -> None:
        out = Twist()
        out.linear.x, out.angular.z = 0.05, float(future.result().message)
        self.cmd.publish(out)


class Planner(Node):
    """Answers ``plan`` with a turn rate that changes each call."""

    def __init__(self):
        super().__init__("planner")
        from std_srvs.srv import Trigger
        self.calls = 0
        self.create_service(Trigger, "plan", self.on_plan)

    def on_plan(self, request, response):
        self.calls += 1
        response.success, response.message = True, str(0.2 * ((self.calls // 4) % 3 - 1))
        return response
