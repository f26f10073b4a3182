"""The callback guard under a multi-threaded executor: two callbacks of one robot may run at once
on two of its threads (rclpy's MultiThreadedExecutor with a reentrant callback group). Each
thread must stay the robot's while its callback runs, whatever the other one does: a thread it
makes (and its ``rclpy.shutdown()``) belongs to the robot, and a hung callback can be interrupted."""
import threading

import numpy as np
import pytest
import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.context import Context
from rclpy.node import Node

from composed_sim.hosting.guard.callback_guard import CallbackGuard
from composed_sim.hosting.guard.node_time import NodeTime


class OneRobot:
    """The guard's view of the simulator node that serves bot0 (callback_guard.ServedRobots)."""

    def __init__(self):
        self.failed = np.zeros(1, dtype=bool)
        self.reasons = []

    def row_of(self, robot):
        return 0

    def mark_failed(self, robot, reason):
        self.failed[0] = True
        self.reasons.append(reason)

    def reject_answer(self, robot, reason):
        pass


@pytest.fixture
def node():
    context = Context()
    rclpy.init(context=context)
    n = Node("two_timers", context=context)
    yield n
    n.destroy_node()
    context.try_shutdown()


def overlapping(node, second_body):
    """The robot's two timer callbacks on two threads: the first ends while the second runs;
    ``second_body(guard, sim)`` runs in the second after that."""
    group = ReentrantCallbackGroup()
    first_in, first_out = threading.Event(), threading.Event()
    seen = {}

    def first():
        first_in.set()
        first_out.wait(5)

    def second():
        first_in.wait(5)
        first_out.set()
        first_thread.join(5)          # the first callback has ended
        seen.update(second_body(guard, sim) or {})
        seen["ended"] = True

    node.create_timer(3600, first, callback_group=group)
    node.create_timer(3600, second, callback_group=group)
    guard, sim = CallbackGuard(1.0, 1.0, NodeTime()), OneRobot()
    guard.guard(node, "bot0", sim)
    timers = list(node.timers)
    first_thread = threading.Thread(target=timers[0].callback)
    second_thread = threading.Thread(target=timers[1].callback)
    first_thread.start()
    second_thread.start()
    second_thread.join(10)
    assert not second_thread.is_alive()
    return seen, sim


def test_a_thread_stays_its_robots_while_another_callback_of_the_robot_ends(node):
    seen, _ = overlapping(node, lambda guard, sim: {"robot": guard.caller_robot(), "inside": guard.in_callback()})
    assert seen == {"robot": "bot0", "inside": True, "ended": True}


def test_a_robots_callback_can_be_interrupted_after_another_of_its_callbacks_ended(node):
    def hang(guard, sim):
        guard.stop_worker("bot0")        # the robot was failed (unresponsive): its callbacks are stopped
        for _ in range(500):
            threading.Event().wait(0.01)  # interruptible: the interruption lands between waits
        return {"not_interrupted": True}
    seen, sim = overlapping(node, hang)
    assert "not_interrupted" not in seen and "ended" not in seen
    assert sim.failed[0] and sim.reasons[0].startswith("hung")
