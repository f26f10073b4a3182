"""A robot's behaviour asks a planner for its command, each in a way ROS 2 users write it: a
blocking call with a timeout, an awaited ``call_async``, a request sent from the constructor, and
a run-wide fleet node's service with a done callback."""
from geometry_msgs.msg import Twist
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from programs_as_written.driving import closeness, twist
from robot_programs_interfaces.srv import Plan


def plan_for(close: float, speed: float = 0.05) -> tuple[float, float]:
    return speed * (1.0 - close), (1.0 if close > 0.3 else 0.0)


class Planner(Node):
    """Serves ``plan``: the command for how close the nearest obstacle is."""

    def __init__(self):
        super().__init__("planner")
        self.srv = self.create_service(Plan, "plan", self.on_plan)

    def on_plan(self, request, response):
        response.linear, response.angular = plan_for(request.closeness)
        self.get_logger().info(f"Incoming request: closeness {request.closeness:.3f}")
        return response


class TimeoutCaller(Node):
    """Calls ``plan`` with ``call(req, timeout_sec=2.0)`` from a scan callback, client and
    subscription in one reentrant group, as under a MultiThreadedExecutor."""

    def __init__(self):
        super().__init__("behaviour")
        group = ReentrantCallbackGroup()
        self.cli = self.create_client(Plan, "plan", callback_group=group)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=group)

    def on_scan(self, scan):
        plan = self.cli.call(Plan.Request(closeness=closeness(scan)), timeout_sec=2.0)
        if plan is None:
            self.get_logger().warn("planner did not answer within 2 s")
            return
        self.cmd.publish(twist(plan.linear, plan.angular))


class AwaitingCaller(Node):
    """An ``async def`` scan callback that awaits ``call_async`` (rclpy's recommended way),
    client and subscription in one reentrant group as rclpy's examples put them."""

    def __init__(self):
        super().__init__("behaviour")
        group = ReentrantCallbackGroup()
        self.cli = self.create_client(Plan, "plan", callback_group=group)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=group)

    async def on_scan(self, scan):
        plan = await self.cli.call_async(Plan.Request(closeness=closeness(scan)))
        self.cmd.publish(twist(plan.linear, plan.angular))


class AwaitingInItsGroup(Node):
    """The same, client and subscription left in the node's default group."""

    def __init__(self):
        super().__init__("behaviour")
        self.cli = self.create_client(Plan, "plan")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    async def on_scan(self, scan):
        plan = await self.cli.call_async(Plan.Request(closeness=closeness(scan)))
        self.cmd.publish(twist(plan.linear, plan.angular))


class ConstructorCaller(Node):
    """Waits for ``plan`` and sends its one request from its constructor (what a ``main()`` does
    right after building the node), logs the result from the future's done callback."""

    def __init__(self):
        super().__init__("asker")
        self.cli = self.create_client(Plan, "plan")
        while not self.cli.wait_for_service(timeout_sec=1.0):
            self.get_logger().info("service not available, waiting again...")
        self.future = self.cli.call_async(Plan.Request(closeness=0.25))
        self.future.add_done_callback(self.on_result)

    def on_result(self, future):
        self.get_logger().info(f"Result of plan: linear {future.result().linear:.4f}")


class FleetOrders(Node):
    """Run-wide: serves ``/fleet/orders`` for every robot."""

    def __init__(self):
        super().__init__("fleet")
        self.create_service(Plan, "/fleet/orders", self.on_order)

    def on_order(self, request, response):
        response.linear, response.angular = plan_for(request.closeness)
        return response


class AsksForOrders(Node):
    """A robot's node: asks ``/fleet/orders`` on each scan with ``call_async`` and a done callback,
    once the service is there (``service_is_ready()``), and publishes the order it gets."""

    def __init__(self):
        super().__init__("behaviour")
        self.cli = self.create_client(Plan, "/fleet/orders")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan):
        if not self.cli.service_is_ready():
            self.get_logger().warn("fleet not ready")
            return
        self.cli.call_async(Plan.Request(closeness=closeness(scan))).add_done_callback(self.on_order)

    def on_order(self, future):
        order = future.result()
        self.cmd.publish(twist(order.linear, order.angular))
