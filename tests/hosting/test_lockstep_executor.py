"""The lockstep executor: fixed dispatch order, answers collected in the same pass, and the
ordinary wait set still serving what direct takes cannot (timers)."""
import time

from rclpy.node import Node
from std_msgs.msg import Int32

from composed_sim.hosting.executors.lockstep import LockstepExecutor


def quiet_node(name, ctx):
    return Node(name, context=ctx, start_parameter_services=False, enable_rosout=False)


def test_callbacks_run_in_node_order_and_answers_are_taken_in_the_same_pass(ros_context):
    executor = LockstepExecutor(context=ros_context)
    seen = []
    source = quiet_node("source", ros_context)
    pub = source.create_publisher(Int32, "/tick", 10)
    workers = []
    for k in (2, 0, 1):                          # added in this order, not by name
        node = quiet_node(f"worker{k}", ros_context)
        answer = node.create_publisher(Int32, f"/answer{k}", 10)
        node.create_subscription(Int32, "/tick",
                                 lambda msg, k=k, answer=answer: (seen.append(("work", k)),
                                                                  answer.publish(Int32(data=k))), 10)
        workers.append(node)
        executor.add_node(node)
    collector = quiet_node("collector", ros_context)
    for k in range(3):
        collector.create_subscription(Int32, f"/answer{k}", lambda msg: seen.append(("answer", msg.data)), 10)
    executor.add_node(collector)
    # Wait until every endpoint is matched, so the published message is ready to take at once.
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() < 3 or any(
            collector.count_publishers(f"/answer{k}") < 1 for k in range(3)):
        assert time.monotonic() < deadline, "endpoints never matched"
        executor.spin_once(timeout_sec=0.01)
    pub.publish(Int32(data=7))
    assert executor.dispatch_ready() == 6
    assert seen == [("work", 2), ("work", 0), ("work", 1), ("answer", 0), ("answer", 1), ("answer", 2)]
    assert executor.dispatch_ready() == 0
    for node in workers + [collector, source]:
        node.destroy_node()
    executor.shutdown()


def test_timers_still_fire_through_the_wait_set(ros_context):
    executor = LockstepExecutor(context=ros_context)
    node = quiet_node("timed", ros_context)
    fired = []
    node.create_timer(0.01, lambda: fired.append(1))
    executor.add_node(node)
    for _ in range(50):
        executor.spin_once(timeout_sec=0.1)
        if len(fired) >= 3:
            break
    assert len(fired) >= 3
    node.destroy_node()
    executor.shutdown()
