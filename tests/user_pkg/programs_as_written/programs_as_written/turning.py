"""An action server that drives its robot while the goal runs, as robot vendors' patrol examples
do: straight ahead paced with ``time.sleep``, then a turn in place that spins the node itself with
``rclpy.spin_once(self, timeout_sec=0.1)`` between commands to read its odometry; a client that
sends the goal from its constructor and, once the result is in, shuts rclpy down from a timer
thread of its own (``threading.Timer(0.1, rclpy.shutdown)``)."""
import math
import threading
import time

import rclpy
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.action import ActionClient, ActionServer, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from robot_programs_interfaces.action import Drive

SPEED = 0.1          # m/s along a side
SIDE_S = 1           # seconds of driving per side
TURN_RATE = 0.8      # rad/s in place
TOLERANCE = 0.02     # rad


def yaw_of(odom: Odometry) -> float:
    q = odom.pose.pose.orientation
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


class SquareServer(Node):
    """Serves ``square``: ``ticks`` sides of a square, one feedback per side."""

    def __init__(self):
        super().__init__("square_server")
        self.cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.odom = None
        self.create_subscription(Odometry, "odom", self.on_odom, 10)
        self.server = ActionServer(self, Drive, "square", self.execute, goal_callback=lambda goal: GoalResponse.ACCEPT,
                                   callback_group=ReentrantCallbackGroup())

    def on_odom(self, msg):
        self.odom = msg

    def send(self, linear: float, angular: float) -> None:
        twist = Twist()
        twist.linear.x, twist.angular.z = linear, angular
        self.cmd.publish(twist)

    def turn_left(self) -> None:
        while self.odom is None:
            rclpy.spin_once(self, timeout_sec=0.1)
        target = yaw_of(self.odom) + math.pi / 2
        while True:
            rclpy.spin_once(self, timeout_sec=0.1)
            left = math.atan2(math.sin(target - yaw_of(self.odom)), math.cos(target - yaw_of(self.odom)))
            if abs(left) < TOLERANCE:
                break
            self.send(0.0, max(-TURN_RATE, min(TURN_RATE, 4.0 * left)))
        self.send(0.0, 0.0)

    def execute(self, goal_handle):
        self.get_logger().info("Executing goal...")
        feedback = Drive.Feedback()
        for side in range(goal_handle.request.ticks):
            self.send(SPEED, 0.0)
            time.sleep(SIDE_S)
            self.send(0.0, 0.0)
            self.turn_left()
            feedback.ticks_left = goal_handle.request.ticks - side - 1
            self.get_logger().info(f"side {side + 1} done, heading {yaw_of(self.odom):.3f}")
            goal_handle.publish_feedback(feedback)
        goal_handle.succeed()
        return Drive.Result(ticks_driven=goal_handle.request.ticks)


class SquareClient(Node):
    """Sends a 4-side goal from its constructor; logs the feedback and the result, then ends its
    process from a timer thread."""

    def __init__(self):
        super().__init__("square_client")
        self.client = ActionClient(self, Drive, "square")
        self.client.wait_for_server()
        self.client.send_goal_async(Drive.Goal(ticks=4), feedback_callback=self.on_feedback) \
            .add_done_callback(self.on_response)

    def on_response(self, future):
        future.result().get_result_async().add_done_callback(self.on_result)

    def on_feedback(self, feedback):
        self.get_logger().info(f"sides left: {feedback.feedback.ticks_left}")

    def on_result(self, future):
        status = future.result().status
        self.get_logger().info(f"Result: {future.result().result.ticks_driven}" if status == GoalStatus.STATUS_SUCCEEDED
                               else f"Goal ended with status {status}")
        threading.Timer(0.1, rclpy.shutdown).start()
