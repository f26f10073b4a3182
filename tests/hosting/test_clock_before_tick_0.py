"""A hosted node's clock before tick 0 reads 0, as a node of a process of its own on sim time
(``use_sim_time``) reads before its first /clock: in its constructor and in the transitions of a
lifecycle node the world file autostarts. (Hosted in this process, the clock read the wall clock
until the host first set it.)"""
import textwrap
from pathlib import Path

import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world
from composed_sim.world.schema import NodeSpec

ROOT = Path(__file__).resolve().parents[2]

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
    package = tmp_path / "clock_probe"
    package.mkdir()
    (package / "__init__.py").write_text(textwrap.dedent(PROBE))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "clock_probe:ClockProbe"


def test_a_hosted_nodes_clock_reads_0_in_its_constructor_and_autostart(clock_probe, domain_id):
    world = load_world(ROOT / "worlds" / "flocking.yaml", robots=1, ticks=2, seed=3)
    group = world.robots[0].model_copy(update={"count": 1, "controller": None, "params": {}, "answers": "when_published",
                                               "nodes": [NodeSpec(node=clock_probe, lifecycle="autostart")]})
    world = world.model_copy(update={"robots": [group]})
    with ComposedHost(world, domain_id=domain_id) as host:
        host.run()
        read = host.controllers[0].read
    assert read == {"constructor": 0, "configure": 0, "activate": 0}
