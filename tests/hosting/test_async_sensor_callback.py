"""An ``async def`` sensor callback of a node that also has a timer runs every tick under every
executor. (The timers' tick counting wrapped it in a plain function, so rclpy's multi-threaded
executor made its coroutine and never ran it: the callback never ran once the node had a timer.)"""
import textwrap
from pathlib import Path

import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world
from composed_sim.world.schema import NodeSpec

ROOT = Path(__file__).resolve().parents[2]
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
    package = tmp_path / "async_scan_probe"
    package.mkdir()
    (package / "__init__.py").write_text(textwrap.dedent(PROBE))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "async_scan_probe:AsyncScan"


@pytest.mark.parametrize("executor", ["lockstep", "multi-threaded"])
def test_an_async_sensor_callback_beside_a_timer_runs_every_tick(async_scan, executor, domain_id):
    world = load_world(ROOT / "worlds" / "flocking.yaml", robots=1, ticks=TICKS, seed=3)
    group = world.robots[0].model_copy(update={"count": 1, "controller": None, "params": {},
                                               "nodes": [NodeSpec(node=async_scan)]})
    world = world.model_copy(update={"robots": [group]})
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        host.run()
        scans = host.controllers[0].scans
    assert scans == [tick * world.tick_ns for tick in range(TICKS)]
