"""A behaviour node asks its robot's planner node (a service) what to do, in each way rclpy offers."""
from geometry_msgs.msg import Twist
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from robot_programs.steering import closeness, steer
from robot_programs_interfaces.srv import Plan


def twist(linear: float, angular: float) -> Twist:
    out = Twist()
    out.linear.x, out.angular.z = linear, angular
    return out


class Planner(Node):
    """Serves ``plan``: the command for how close the nearest obstacle is."""

    def __init__(self):
        super().__init__("planner")
        self.calls = 0
        self.create_service(Plan, "plan", self.on_plan)

    def on_plan(self, request, response):
        self.calls += 1
        response.linear, response.angular = steer(request.closeness)
        return response


class _Behaviour(Node):
    def __init__(self, name: str, group=None):
        super().__init__(name)
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.client = self.create_client(Plan, "plan", callback_group=group)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=group)

    def request(self, scan) -> Plan.Request:
        return Plan.Request(closeness=closeness(scan))


class BlockingBehaviour(_Behaviour):
    """``Client.call()`` from the scan callback, both in a reentrant group: the pattern of rclpy's
    MultiThreadedExecutor (another thread runs the planner and takes the response meanwhile)."""

    def __init__(self):
        super().__init__("behaviour", ReentrantCallbackGroup())

    def on_scan(self, scan):
        plan = self.client.call(self.request(scan))
        self.cmd.publish(twist(plan.linear, plan.angular))


class AsyncBehaviour(_Behaviour):
    """An ``async def`` scan callback that awaits ``call_async``, rclpy's recommended way; the
    client in a group of its own, so that its response can be taken while the callback waits."""

    def __init__(self):
        super().__init__("behaviour")
        self.client = self.create_client(Plan, "plan", callback_group=ReentrantCallbackGroup())

    async def on_scan(self, scan):
        plan = await self.client.call_async(self.request(scan))
        self.cmd.publish(twist(plan.linear, plan.angular))


class FutureBehaviour(_Behaviour):
    """``call_async`` with a done callback."""

    def __init__(self):
        super().__init__("behaviour")

    def on_scan(self, scan):
        self.client.call_async(self.request(scan)).add_done_callback(self.on_plan)

    def on_plan(self, future):
        plan = future.result()
        self.cmd.publish(twist(plan.linear, plan.angular))


class SameGroupBehaviour(_Behaviour):
    """``Client.call()`` from a callback of the node's default (mutually exclusive) group, which
    must also take the response: it waits forever in any process."""

    def __init__(self):
        super().__init__("behaviour")

    def on_scan(self, scan):
        plan = self.client.call(self.request(scan))
        self.cmd.publish(twist(plan.linear, plan.angular))


class SpinsItself(_Behaviour):
    """Spins itself in a thread of its own, as a node written to run alone sometimes does."""

    def __init__(self):
        import threading
        from rclpy.executors import MultiThreadedExecutor
        super().__init__("behaviour")
        self.own_executor = MultiThreadedExecutor(context=self.context)
        self.own_executor.add_node(self)
        threading.Thread(target=self.own_executor.spin, daemon=True).start()

    def on_scan(self, scan):
        self.client.call_async(self.request(scan))


class TutorialClient(_Behaviour):
    """Waits for its service in its constructor, as the ROS 2 tutorials' clients do, although the
    planner is built after it."""

    def __init__(self):
        super().__init__("behaviour", ReentrantCallbackGroup())
        while not self.client.wait_for_service(timeout_sec=1.0):
            self.get_logger().info("service not available, waiting again...")

    def on_scan(self, scan):
        plan = self.client.call(self.request(scan))
        self.cmd.publish(twist(plan.linear, plan.angular))


class LateLookup(Node):
    """Steers by itself; on its first scan makes a client for a service nobody serves and asks,
    briefly, whether it is there (``found``): no, in any process."""

    def __init__(self):
        super().__init__("behaviour")
        self.found = None
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan):
        if self.found is None:
            self.found = self.create_client(Plan, "no_such_plan").wait_for_service(timeout_sec=0.05)
        self.cmd.publish(twist(*steer(closeness(scan))))
