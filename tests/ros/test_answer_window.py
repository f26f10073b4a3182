"""The simulator node's answer window: a tick closes once every robot still expected has answered."""
import math

from geometry_msgs.msg import TwistStamped

from composed_sim.core.simulation import Simulation
from composed_sim.ros import contract as c
from composed_sim.world.loader import world_from_dict


def test_a_robot_failed_by_its_answer_does_not_close_the_tick_for_the_others(ros_context):
    """bot1's first answer is non-finite and max_violations is 1: bot1 is failed while its answer is
    handled. The tick must still wait for bot0 (it once closed at once, and bot0's answer, still
    on its way, was recorded as missed: a flaky multi-process test)."""
    from rclpy.node import Node
    from composed_sim.hosting.executors.lockstep import LockstepExecutor
    from composed_sim.ros.simulator_node import SimulatorNode
    world = world_from_dict({"name": "window", "length_ticks": 5, "lockstep": {"max_violations": 1},
                             "robots": [{"count": 2, "controller": "x"}]})
    sim = Simulation(world)
    controller = Node("controller", context=ros_context)     # both robots' controller, for the test
    answers = {robot: controller.create_publisher(TwistStamped, f"/{robot}/cmd_vel", c.QOS) for robot in sim.names}
    node = SimulatorNode(sim.names, sim.models, context=ros_context, tick_ns=world.tick_ns, lockstep=world.lockstep)
    executor = LockstepExecutor(context=ros_context)
    executor.add_node(node)
    try:
        node.publish_tick(sim.step())
        answer = TwistStamped()
        answer.header.stamp = c.stamp_of(sim.tick, world.tick_ns)
        answer.twist.linear.x = math.nan
        answers["bot1"].publish(answer)
        assert executor.dispatch_ready() == 1
        assert node.failed.tolist() == [False, True] and not node.all_answered
        answer.twist.linear.x = 0.1
        answers["bot0"].publish(answer)
        assert executor.dispatch_ready() == 1
        assert node.all_answered and node.answered.tolist() == [True, False]
        assert [(v.robot, v.reason.split(" (")[0]) for v in node.violations] == [
            ("bot1", "non-finite velocity command rejected"),
            ("bot1", "controller failed: stopped after 1 violations")]
    finally:
        executor.shutdown()
        node.destroy_node()
        controller.destroy_node()
