"""A mission node gives its robot's driver node goals (an action) and cancels one when an
obstacle comes close; the driver drives a goal tick by tick on the robot's clock."""
from geometry_msgs.msg import Twist
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from robot_programs.planning import twist
from robot_programs.steering import closeness, steer
from robot_programs_interfaces.action import Drive

TICK_HZ = 10.0          # the worlds' tick


class Driver(Node):
    """Serves ``drive``: publishes the goal's command once per tick of its clock, with feedback,
    until the goal's ticks are done or it is cancelled. The execute callback blocks on a rate's
    ``sleep()`` in a reentrant group, as under rclpy's MultiThreadedExecutor."""

    def __init__(self):
        super().__init__("driver")
        group = ReentrantCallbackGroup()
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.rate = self.create_rate(TICK_HZ)
        self.server = ActionServer(self, Drive, "drive", self.execute, callback_group=group,
                                   goal_callback=self.on_goal, cancel_callback=lambda goal: CancelResponse.ACCEPT)
        self.goals = self.cancelled = 0

    def on_goal(self, request) -> GoalResponse:
        return GoalResponse.ACCEPT if request.ticks > 0 else GoalResponse.REJECT

    def execute(self, goal):
        self.goals += 1
        request, feedback = goal.request, Drive.Feedback()
        driven = 0
        while driven < request.ticks:
            if goal.is_cancel_requested:
                goal.canceled()
                self.cancelled += 1
                self.cmd.publish(twist(0.0, 1.0))           # turn away on the spot
                return Drive.Result(ticks_driven=driven)
            self.cmd.publish(twist(request.linear, request.angular))
            driven += 1
            feedback.ticks_left = request.ticks - driven
            goal.publish_feedback(feedback)
            self.rate.sleep()
        goal.succeed()
        return Drive.Result(ticks_driven=driven)


class Mission(Node):
    """Sends a 5-tick goal whenever none is active, from the latest scan; cancels the active goal
    when something comes close. Everything through futures' done callbacks."""

    def __init__(self):
        super().__init__("mission")
        self.client = ActionClient(self, Drive, "drive")
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.goal_handle = None
        self.sending = False
        self.feedback = self.results = self.rejected = 0

    def on_scan(self, scan):
        close = closeness(scan)
        if self.goal_handle is not None and close > 0.5:
            self.goal_handle.cancel_goal_async()
            self.goal_handle = None
        if self.goal_handle is None and not self.sending:
            linear, angular = steer(close)
            self.sending = True
            self.client.send_goal_async(Drive.Goal(linear=linear, angular=angular, ticks=5),
                                        feedback_callback=self.on_feedback).add_done_callback(self.on_accepted)

    def on_feedback(self, feedback):
        self.feedback += 1

    def on_accepted(self, future):
        self.sending = False
        handle = future.result()
        if not handle.accepted:
            self.rejected += 1
            return
        self.goal_handle = handle
        handle.get_result_async().add_done_callback(lambda result, handle=handle: self.on_result(handle))

    def on_result(self, handle):
        self.results += 1
        if self.goal_handle is handle:
            self.goal_handle = None


class BlockingMission(Node):
    """Sends each goal with the blocking ``send_goal()`` and waits for its result with
    ``get_result()``, from a reentrant scan callback: one goal at a time."""

    def __init__(self):
        super().__init__("mission")
        group = ReentrantCallbackGroup()
        self.client = ActionClient(self, Drive, "drive", callback_group=group)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10, callback_group=group)
        self.busy = False
        self.results = []

    def on_scan(self, scan):
        if self.busy:
            return
        self.busy = True
        linear, angular = steer(closeness(scan))
        handle = self.client.send_goal(Drive.Goal(linear=linear, angular=angular, ticks=3))
        self.results.append(handle.get_result().result.ticks_driven)
        self.busy = False


class QuickDriver(Node):
    """Serves ``drive`` at once: one command, one feedback, the result (an ``async def`` execute
    callback that awaits nothing is fine too)."""

    def __init__(self):
        super().__init__("driver")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.server = ActionServer(self, Drive, "drive", self.execute)

    async def execute(self, goal):
        self.cmd.publish(twist(goal.request.linear, goal.request.angular))
        goal.publish_feedback(Drive.Feedback(ticks_left=0))
        goal.succeed()
        return Drive.Result(ticks_driven=1)


class AwaitingMission(Node):
    """A one-tick goal per scan, awaited: ``await send_goal_async`` then ``await get_result_async``,
    the client in a group of its own."""

    def __init__(self):
        super().__init__("mission")
        self.client = ActionClient(self, Drive, "drive", callback_group=ReentrantCallbackGroup())
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.feedback = self.results = 0

    async def on_scan(self, scan):
        linear, angular = steer(closeness(scan))
        handle = await self.client.send_goal_async(Drive.Goal(linear=linear, angular=angular, ticks=1),
                                                   feedback_callback=self.on_feedback)
        result = await handle.get_result_async()
        self.results += result.result.ticks_driven

    def on_feedback(self, feedback):
        self.feedback += 1
