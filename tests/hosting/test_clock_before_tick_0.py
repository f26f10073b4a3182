"""A hosted node's clock before tick 0 reads 0, as a node of a process of its own on sim time
(``use_sim_time``) reads before its first /clock: in its constructor and in the transitions of a
lifecycle node the world file autostarts. (Hosted in this process, the clock read the wall clock
until the host first set it.)"""
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.schema import NodeSpec
from tests.hosting.probes import one_robot_world, probe_package


PROBE = '''
from geometry_msgs.msg import TwistStamped
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn


class ClockProbe(LifecycleNode):
    def __init__(self):
        super().__init__("clock_probe")
        self.read = {"constructor": self.get_clock().now().nanoseconds}

    def on_configure(self, state):
        self.read["configure"] = self.get_clock().now().nanoseconds
        self.create_lifecycle_publisher(TwistStamped, "cmd_vel", 10)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        self.read["activate"] = self.get_clock().now().nanoseconds
        return super().on_activate(state)
'''


@pytest.fixture
def clock_probe(tmp_path, monkeypatch):
    yield from probe_package(tmp_path, monkeypatch, "clock_probe", PROBE)


def test_a_hosted_nodes_clock_reads_0_in_its_constructor_and_autostart(clock_probe, domain_id):
    world = one_robot_world(NodeSpec(node=f"{clock_probe}:ClockProbe", lifecycle="autostart"), 2,
                            answers="when_published")
    with ComposedHost(world, domain_id=domain_id) as host:
        host.run()
        read = host.controllers[0].read
    assert read == {"constructor": 0, "configure": 0, "activate": 0}
