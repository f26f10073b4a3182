"""A robot whose behaviour node asks its planner node what to do, every tick, through a service
call that blocks in a reentrant callback group (the pattern of rclpy's MultiThreadedExecutor), and
the same logic in one node: the bench's planner-service and planner-inline experiments, which
show what a service call between a robot's nodes costs the host (docs/speed.md).

Plain rclpy nodes with standard messages only: the plan is a ``nav_msgs/GetPlan`` whose goal's x
says how close the nearest obstacle is and whose first pose's x and y are the speed and the turn
rate. Foot-bots steer by their proximity ring: drive on, slower as something comes close, turn
away once it is close.
"""
from __future__ import annotations

from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.srv import GetPlan
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


def plan_for(closeness: float, speed: float) -> tuple[float, float]:
    """(speed m/s, turn rate rad/s) for how close (0 … 1) the nearest obstacle is."""
    return speed * (1.0 - closeness), (1.5 if closeness > 0.3 else 0.0)


def closeness_of(scan: LaserScan) -> float:
    return max(scan.intensities) if len(scan.intensities) else 0.0


def twist(linear: float, angular: float) -> Twist:
    out = Twist()
    out.linear.x, out.angular.z = linear, angular
    return out


class AvoidancePlanner(Node):
    """Serves ``plan``: the command for the closeness in the request's goal."""

    def __init__(self, **kwargs):
        super().__init__("planner", **kwargs)
        self.speed = self.declare_parameter("speed_mps", 0.1).value
        self.create_service(GetPlan, "plan", self.on_plan)

    def on_plan(self, request: GetPlan.Request, response: GetPlan.Response) -> GetPlan.Response:
        step = PoseStamped()
        step.pose.position.x, step.pose.position.y = plan_for(request.goal.pose.position.x, self.speed)
        response.plan.poses = [step]
        return response


class PlanningBehaviour(Node):
    """On each scan, calls ``plan`` and waits for it (``Client.call`` in a reentrant group), then
    drives as planned."""

    def __init__(self, **kwargs):
        super().__init__("behaviour", **kwargs)
        group = ReentrantCallbackGroup()
        self.client = self.create_client(GetPlan, "plan", callback_group=group)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=group)
        self.request = GetPlan.Request()

    def on_scan(self, scan: LaserScan) -> None:
        self.request.goal.pose.position.x = closeness_of(scan)
        step = self.client.call(self.request).plan.poses[0].pose.position
        self.cmd.publish(twist(step.x, step.y))


class InlinePlanning(Node):
    """The same decision, made in the scan callback itself: one node, no call."""

    def __init__(self, **kwargs):
        super().__init__("behaviour", **kwargs)
        self.speed = self.declare_parameter("speed_mps", 0.1).value
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan: LaserScan) -> None:
        self.cmd.publish(twist(*plan_for(closeness_of(scan), self.speed)))
