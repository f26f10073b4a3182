"""A sensor callback of a mutually exclusive group that sleeps on the node's clock wakes when the
clock gets there, as in its own process, and the next reading's callback runs then. (The wake-up
timer was on the clock that moves once the tick's sensor callbacks have returned: the sleeping one
had not, the next could not start, so it never woke and the robot stopped hearing its sensors.)"""
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.schema import NodeSpec
from tests.hosting.probes import one_robot_world, probe_package

TICKS = 6

PROBE = '''
from geometry_msgs.msg import TwistStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class SleepyScan(Node):
    def __init__(self):
        super().__init__("sleepy_scan")
        self.log = []
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10,
                                 callback_group=MutuallyExclusiveCallbackGroup())

    def on_scan(self, msg):
        tick = msg.header.stamp.nanosec // 100_000_000
        self.log.append(("scan", tick))
        self.cmd.publish(TwistStamped(header=msg.header))
        self.get_clock().sleep_for(Duration(nanoseconds=100_000_000))     # one tick
        self.log.append(("woke", self.get_clock().now().nanoseconds // 100_000_000))
'''


@pytest.fixture
def sleepy_scan(tmp_path, monkeypatch):
    yield from probe_package(tmp_path, monkeypatch, "sleepy_scan_probe", PROBE)


def test_a_sleeping_sensor_callback_of_a_mutually_exclusive_group_wakes_a_tick_later(sleepy_scan, domain_id):
    world = one_robot_world(NodeSpec(node=f"{sleepy_scan}:SleepyScan"), TICKS, answers="when_published")
    assert world.tick_ns == 100_000_000
    with ComposedHost(world, domain_id=domain_id) as host:
        host.run()
        log = host.controllers[0].log
    # Each reading's callback runs the tick the one before woke in (its reading waited meanwhile).
    assert log[:2 * (TICKS - 1)] == [event for tick in range(TICKS - 1) for event in (("scan", tick), ("woke", tick + 1))]
