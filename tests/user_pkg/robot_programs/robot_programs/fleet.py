"""Run-wide nodes that robots call and that call robots: a fleet planner every robot asks each
tick, and a node that changes each robot's speed through its parameter services."""
from geometry_msgs.msg import Twist
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import LaserScan

from robot_programs.planning import twist
from robot_programs.steering import closeness, steer
from robot_programs_interfaces.srv import Plan


class FleetPlanner(Node):
    """Run-wide: serves ``/fleet/plan`` for every robot."""

    def __init__(self):
        super().__init__("fleet_planner")
        self.calls = 0
        self.create_service(Plan, "/fleet/plan", self.on_plan)

    def on_plan(self, request, response):
        self.calls += 1
        response.linear, response.angular = steer(request.closeness)
        return response


class AsksTheFleet(Node):
    """A robot's node: asks ``/fleet/plan`` on each scan, drives as the response says."""

    def __init__(self):
        super().__init__("behaviour")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.client = self.create_client(Plan, "/fleet/plan")
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan):
        future = self.client.call_async(Plan.Request(closeness=closeness(scan)))
        future.add_done_callback(lambda f: self.cmd.publish(twist(f.result().linear, f.result().angular)))


class SpeedFollower(Node):
    """A robot's node whose ``speed`` parameter may be set at run time (it refuses a negative one)."""

    def __init__(self):
        super().__init__("behaviour")
        self.speed = self.declare_parameter("speed", 0.02).value
        self.add_on_set_parameters_callback(self.on_set)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_set(self, parameters):
        for p in parameters:
            if p.name == "speed" and p.value < 0:
                return SetParametersResult(successful=False, reason="speed must not be negative")
        for p in parameters:
            if p.name == "speed":
                self.speed = p.value
        return SetParametersResult(successful=True)

    def on_scan(self, scan):
        self.cmd.publish(twist(*steer(closeness(scan), self.speed)))


class SpeedSetter(Node):
    """Run-wide: every ``period`` s sets each robot's ``behaviour`` speed to the next of ``speeds``
    through its ``set_parameters`` service, as ``ros2 param set`` would; keeps the results."""

    def __init__(self):
        super().__init__("speed_setter")
        robots = self.declare_parameter("robots", ["bot0"]).value
        self.speeds = self.declare_parameter("speeds", [0.06, -1.0, 0.03]).value
        period = self.declare_parameter("period", 1.0).value
        self.clients_ = [AsyncParameterClient(self, f"/{r}/behaviour") for r in robots]
        self.results = []
        self.step = 0
        self.create_timer(period, self.set_next)

    def set_next(self):
        if self.step >= len(self.speeds):
            return
        speed = self.speeds[self.step]
        self.step += 1
        for client in self.clients_:
            future = client.set_parameters([Parameter("speed", value=speed)])
            future.add_done_callback(lambda f: self.results.append(
                [(r.successful, r.reason) for r in f.result().results]))
