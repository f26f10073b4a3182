"""The simulator's cmd_vel subscription (ros/answer_subscription.py) as two threads use it: a
multi-threaded executor's and the simulator's own, which takes what is ready before it settles
the robots that answer when published."""
import threading
import time

from geometry_msgs.msg import Twist
from rclpy.node import Node

from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import AnswerSubscription


def test_a_thread_that_finds_no_answer_waits_for_one_taken_by_another_and_not_yet_handled(ros_context):
    node = Node("simulator", context=ros_context)
    entered, release, handled = threading.Event(), threading.Event(), []

    def on_answer(data, gid):
        if threading.current_thread().name == "executor":
            entered.set()
            release.wait(5.0)          # descheduled between its take and its callback's end
        handled.append(data)

    sub = AnswerSubscription(node, Twist, "/bot0/cmd_vel", c.QOS, on_answer)
    publisher = node.create_publisher(Twist, "/bot0/cmd_vel", c.QOS)
    deadline = time.monotonic() + 5.0
    while sub.get_publisher_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    publisher.publish(Twist())

    def executor_thread():
        while not sub.dispatch_ready() and time.monotonic() < deadline:
            time.sleep(0.001)

    executor = threading.Thread(target=executor_thread, name="executor")
    executor.start()
    assert entered.wait(5.0)
    simulator_took = []
    simulator = threading.Thread(target=lambda: simulator_took.append(sub.dispatch_ready()))
    simulator.start()
    simulator.join(0.2)
    # The simulator's take does not come back empty while the answer is being handled...
    assert simulator.is_alive() and handled == []
    release.set()
    simulator.join(5.0)
    executor.join(5.0)
    # ...and when it does, the answer is handled: the robot is not settled as quiet before it.
    assert simulator_took == [0] and len(handled) == 1
    sub.destroy(node)
    node.destroy_node()
