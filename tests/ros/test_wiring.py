"""What the simulator says it sees of a robot's controller, for start-up errors that name what is
missing (multi-process and external controllers, whose endpoints appear late)."""
import time

from rclpy.node import Node
from sensor_msgs.msg import LaserScan

from composed_sim.ros.simulator_node import SimulatorNode
from composed_sim.world.robot_models import get_model


def test_the_simulator_names_what_it_sees_of_a_robots_controller(ros_context):
    sim = SimulatorNode(["bot0"], [get_model("foot-bot")], context=ros_context, tick_ns=100_000_000)
    controller = Node("controller", namespace="/bot0", context=ros_context)
    try:
        assert sim.connection_of("bot0") == ("bot0: no cmd_vel publisher, no subscriber on any of its sensors "
                                             "(/bot0/proximity, /bot0/light, /bot0/blobs)")
        controller.create_subscription(LaserScan, "proximity", lambda msg: None, 10)
        deadline = time.monotonic() + 10
        while "subscribers on" not in sim.connection_of("bot0") and time.monotonic() < deadline:
            time.sleep(0.01)      # matching is Fast DDS's, in its own threads
        assert sim.connection_of("bot0") == "bot0: no cmd_vel publisher, subscribers on /bot0/proximity"
    finally:
        controller.destroy_node()
        sim.destroy_node()
