"""An ``async def`` sensor callback of a node that also has a timer runs every tick under every
executor. (The timers' tick counting wrapped it in a plain function, so rclpy's multi-threaded
executor made its coroutine and never ran it: the callback never ran once the node had a timer.)"""
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.schema import NodeSpec
from tests.hosting.probes import one_robot_world, probe_package

TICKS = 6

PROBE = '''
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class AsyncScan(Node):
    def __init__(self):
        super().__init__("async_scan")
        self.scans = []
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)
        self.create_timer(0.3, lambda: None)

    async def on_scan(self, msg):
        self.scans.append(msg.header.stamp.nanosec)
        self.cmd.publish(TwistStamped(header=msg.header))
'''


@pytest.fixture
def async_scan(tmp_path, monkeypatch):
    yield from probe_package(tmp_path, monkeypatch, "async_scan_probe", PROBE)


@pytest.mark.parametrize("executor", ["lockstep", "multi-threaded"])
def test_an_async_sensor_callback_beside_a_timer_runs_every_tick(async_scan, executor, domain_id):
    world = one_robot_world(NodeSpec(node=f"{async_scan}:AsyncScan"), TICKS)
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        host.run()
        scans = host.controllers[0].scans
    assert scans == [tick * world.tick_ns for tick in range(TICKS)]
