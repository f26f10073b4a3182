"""Actions between a robot's nodes as users write them: servers that pace their feedback with
``time.sleep`` (the common way) or with a sleep on the node's clock, one that queues goals; clients
that log what they hear, cancel a goal, send two goals at once, or shut rclpy down once done."""
import collections
import threading
import time

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node

from robot_programs_interfaces.action import Drive

PAUSE_S = 0.3       # between two feedbacks


class Pacer(Node):
    """Serves ``pace``: one feedback per step of the goal, a pause between them (``time.sleep``,
    the common way; with parameter ``sleep_on: clock`` a sleep on the node's clock; ``none``: no pause), in a
    reentrant group so that other goals and cancels are handled meanwhile (MultiThreadedExecutor)."""

    def __init__(self):
        super().__init__("pacer")
        self.sleep_on = self.declare_parameter("sleep_on", "wall").value
        self.server = self.make_server()

    def make_server(self) -> ActionServer:
        return ActionServer(self, Drive, "pace", execute_callback=self.execute, goal_callback=self.on_goal,
                            cancel_callback=self.on_cancel, callback_group=ReentrantCallbackGroup())

    def on_goal(self, request):
        self.get_logger().info("Received goal request")
        return GoalResponse.ACCEPT

    def on_cancel(self, goal_handle):
        self.get_logger().info("Received cancel request")
        return CancelResponse.ACCEPT

    def pause(self):
        if self.sleep_on == "none":
            return
        if self.sleep_on == "clock":
            self.get_clock().sleep_for(Duration(seconds=PAUSE_S))
        else:
            time.sleep(PAUSE_S)

    def execute(self, goal_handle):
        self.get_logger().info("Executing goal...")
        feedback = Drive.Feedback()
        for step in range(goal_handle.request.ticks):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                self.get_logger().info("Goal canceled")
                return Drive.Result(ticks_driven=step)
            feedback.ticks_left = goal_handle.request.ticks - step - 1
            self.get_logger().info(f"Publishing feedback: {feedback.ticks_left}")
            goal_handle.publish_feedback(feedback)
            self.pause()
        goal_handle.succeed()
        self.get_logger().info("Returning result")
        return Drive.Result(ticks_driven=goal_handle.request.ticks)


class QueueingPacer(Pacer):
    """The same, one goal at a time: a goal accepted while another executes waits in a queue."""

    def make_server(self) -> ActionServer:
        self.queue = collections.deque()
        self.lock = threading.Lock()
        self.current = None
        return ActionServer(self, Drive, "pace", execute_callback=self.execute_next,
                            handle_accepted_callback=self.on_accepted, goal_callback=self.on_goal,
                            cancel_callback=self.on_cancel, callback_group=ReentrantCallbackGroup())

    def on_accepted(self, goal_handle):
        with self.lock:
            if self.current is not None:
                self.queue.append(goal_handle)
                self.get_logger().info("Goal put in the queue")
                return
            self.current = goal_handle
        goal_handle.execute()

    def execute_next(self, goal_handle):
        try:
            return self.execute(goal_handle)
        finally:
            with self.lock:
                self.current = self.queue.popleft() if self.queue else None
            if self.current is not None:
                self.get_logger().info("Next goal pulled from the queue")
                self.current.execute()


class PaceClient(Node):
    """Sends one 3-step goal from its first timer callback; logs acceptance, each feedback and
    the result. Parameter ``action``: the server's action name (``pace``, its robot's)."""

    steps = 3

    def __init__(self):
        super().__init__("pace_client")
        self.client = ActionClient(self, Drive, self.declare_parameter("action", "pace").value)
        self.timer = self.create_timer(0.1, self.send)

    def send(self):
        self.timer.cancel()
        self.client.wait_for_server()
        self.get_logger().info("Sending goal request...")
        self.client.send_goal_async(Drive.Goal(ticks=self.steps), feedback_callback=self.on_feedback) \
            .add_done_callback(self.on_response)

    def on_response(self, future):
        handle = future.result()
        if not handle.accepted:
            self.get_logger().info("Goal rejected")
            return
        self.get_logger().info("Goal accepted")
        self.accepted(handle)

    def accepted(self, handle):
        handle.get_result_async().add_done_callback(self.on_result)

    def on_feedback(self, feedback):
        self.get_logger().info(f"Received feedback: {feedback.feedback.ticks_left}")

    def on_result(self, future):
        status = future.result().status
        if status == GoalStatus.STATUS_SUCCEEDED:
            self.get_logger().info(f"Goal succeeded: {future.result().result.ticks_driven}")
        else:
            self.get_logger().info(f"Goal ended with status {status}")


class CancellingClient(PaceClient):
    """Sends a 6-step goal and cancels it 0.5 s after it was accepted."""

    steps = 6

    def accepted(self, handle):
        self.goal_handle = handle
        self.cancel_timer = self.create_timer(0.5, self.cancel)

    def cancel(self):
        self.cancel_timer.cancel()
        self.get_logger().info("Canceling goal")
        self.goal_handle.cancel_goal_async().add_done_callback(self.on_cancelled)

    def on_cancelled(self, future):
        if len(future.result().goals_canceling) > 0:
            self.get_logger().info("Goal successfully canceled")
        else:
            self.get_logger().info("Goal failed to cancel")


class TwoGoalsClient(PaceClient):
    """Sends two 2-step goals at once."""

    steps = 2

    def send(self):
        super().send()
        self.client.send_goal_async(Drive.Goal(ticks=self.steps), feedback_callback=self.on_feedback) \
            .add_done_callback(self.on_response)


class ShuttingDownClient(PaceClient):
    """As the ROS 2 examples' action client: ``rclpy.shutdown()`` once the result is in."""

    steps = 2

    def on_result(self, future):
        super().on_result(future)
        rclpy.shutdown()


class FleetDispatcher(Node):
    """A fleet manager: sends each robot's ``pace`` server (parameter ``robots``) a 3-step goal from
    its first timer callback, and logs what it hears of each, robot by robot."""

    def __init__(self):
        super().__init__("dispatcher")
        robots = self.declare_parameter("robots", ["bot0", "bot1"]).value
        self.action_clients = {robot: ActionClient(self, Drive, f"/{robot}/pace") for robot in robots}
        self.timer = self.create_timer(0.1, self.send)

    def send(self):
        self.timer.cancel()
        for robot, client in self.action_clients.items():
            client.wait_for_server()
            self.get_logger().info(f"{robot}: sending goal")
            client.send_goal_async(Drive.Goal(ticks=3), feedback_callback=lambda feedback, robot=robot:
                                   self.get_logger().info(f"{robot}: feedback {feedback.feedback.ticks_left}")) \
                .add_done_callback(lambda future, robot=robot: self.on_response(robot, future))

    def on_response(self, robot, future):
        handle = future.result()
        self.get_logger().info(f"{robot}: goal {'accepted' if handle.accepted else 'rejected'}")
        handle.get_result_async().add_done_callback(lambda done: self.get_logger().info(
            f"{robot}: result {done.result().result.ticks_driven}, status {done.result().status}"))
