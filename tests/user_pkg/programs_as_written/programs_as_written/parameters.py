"""Parameters set at run time across places: a run-wide node sets each robot's ``speed`` through
the robot node's ``set_parameters`` service once ``service_is_ready()``, and a robot's node waits
for its sibling's parameter services with ``AsyncParameterClient.wait_for_services()``."""
from geometry_msgs.msg import Twist
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import LaserScan

from programs_as_written.driving import closeness, twist


class Tunable(Node):
    """A robot's node that drives at its ``speed`` parameter (0 until set), which may be set at
    run time."""

    def __init__(self):
        super().__init__("tunable")
        self.speed = self.declare_parameter("speed", 0.0).value
        self.add_on_set_parameters_callback(self.on_set)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_set(self, parameters):
        for p in parameters:
            if p.name == "speed":
                self.speed = p.value
                now_s = self.get_clock().now().nanoseconds * 1e-9
                self.get_logger().info(f"speed set to {p.value} at {now_s:g} s")
        return SetParametersResult(successful=True)

    def on_scan(self, scan):
        self.cmd.publish(twist(self.speed * (1.0 - closeness(scan))))


class SpeedDispatcher(Node):
    """Run-wide: every second, for each robot whose ``tunable/set_parameters`` service is ready,
    sets ``speed`` to 0.05 (once); says so when one is not ready."""

    def __init__(self):
        super().__init__("dispatcher")
        robots = self.declare_parameter("robots", ["bot0", "bot1"]).value
        self.clients_ = {r: self.create_client(SetParameters, f"/{r}/tunable/set_parameters") for r in robots}
        self.done = set()
        self.create_timer(1.0, self.dispatch)

    def dispatch(self):
        for robot, cli in self.clients_.items():
            if robot in self.done:
                continue
            if not cli.service_is_ready():
                self.get_logger().warn(f"parameter services of {robot} not ready")
                continue
            value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.05)
            request = SetParameters.Request(parameters=[ParameterMsg(name="speed", value=value)])
            cli.call_async(request).add_done_callback(
                lambda f, robot=robot: self.get_logger().info(f"{robot}: set {f.result().results[0].successful}"))
            self.done.add(robot)


class WaitingTuner(Node):
    """A robot's node that makes an ``AsyncParameterClient`` for its sibling ``tunable`` node and
    waits for its services in its constructor (rclpy's demo's pattern), then sets its speed."""

    def __init__(self):
        super().__init__("tuner")
        self.client = AsyncParameterClient(self, "tunable")
        if not self.client.wait_for_services(timeout_sec=2.0):
            raise RuntimeError("tunable is not available")
        self.client.set_parameters([Parameter("speed", value=0.05)]).add_done_callback(
            lambda f: self.get_logger().info(f"set: {f.result().results[0].successful}"))
