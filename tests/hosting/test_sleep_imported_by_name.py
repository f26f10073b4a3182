"""``from time import sleep`` at the top of a node's module sleeps on the run's clock, as
``time.sleep`` does (hosting/sim_time/sleeps.py): the rule is in place before any node module is
imported, on every path that imports them. ``composed-sim run`` imported the world's node modules
to check them (cli/common.py) before the host rebound ``time.sleep``, so in one process a module
that had bound the name kept the wall clock's: its callback held up the whole host and its clock
stood still while it slept. Run as a user runs it, in a process of its own (this test process has
rebound ``time.sleep`` long ago)."""
import os
import re
import subprocess
import sys

import pytest
import yaml

from tests.hosting.probes import FLOCKING, probe_package

PROBE = '''
import time
from time import sleep

from geometry_msgs.msg import TwistStamped
from rclpy.node import Node


class Sleeper(Node):
    """Sleeps 0.3 s in its first timer call, once by the name it imported and once by the module's."""

    def __init__(self):
        super().__init__("sleeper")
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.calls = 0
        self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        self.calls += 1
        if self.calls == 2:
            for how, wait in (("by name", sleep), ("time.sleep", time.sleep)):
                before = self.get_clock().now().nanoseconds
                wait(0.3)
                self.get_logger().info(f"{how} slept {(self.get_clock().now().nanoseconds - before) / 1e9:.1f} s")
        msg = TwistStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        self.cmd.publish(msg)
'''


@pytest.fixture
def sleeper(tmp_path, monkeypatch):
    yield from probe_package(tmp_path, monkeypatch, "sleeper_probe", PROBE)


@pytest.mark.parametrize("mode", [["--workers", "1"], ["--workers", "2"]])
def test_sleep_bound_by_name_sleeps_on_the_runs_clock_as_time_sleep_does(sleeper, tmp_path, mode, domain_id):
    world = yaml.safe_load(FLOCKING.read_text())
    world["robots"][0].update({"count": 2, "nodes": [{"node": f"{sleeper}:Sleeper"}], "answers": "when_published"})
    world["robots"][0].pop("controller", None)
    world["robots"][0].pop("params", None)
    world.pop("loop_functions", None)
    path = tmp_path / "sleeper.yaml"
    path.write_text(yaml.safe_dump(world))
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(path), "--ticks", "12", *mode,
                           "--domain-id", str(domain_id), "--out", str(out), "--no-progress", "--no-picture"],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert done.returncode == 0, done.stderr[-3000:]
    for robot_log in sorted((out / "logs").glob("*.log")):
        slept = dict(re.findall(r"(by name|time\.sleep) slept ([0-9.]+) s", robot_log.read_text()))
        assert slept == {"by name": "0.3", "time.sleep": "0.3"}, robot_log.read_text()
