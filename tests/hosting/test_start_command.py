"""A swarm package as ROS 2 swarm packages are written (a TurtleBot 3's LiDAR layer → a dispersion
pattern → a hardware-protection layer, chained by topics, the last alone publishing cmd_vel, a
parameters file), whose pattern waits for a run-wide start command: a run-wide node publishes it
from its constructor (tick 0) or, as issue 55's package did, from a timer (at its first period, as
rclpy fires it: tick 1). Until then the robots have had no chance to answer; no robot misses a tick,
tick 0 included, in any host mode. (Regression of ed7d48f: its timer phase made the run-wide
timer's start command go at tick 1, and every robot missed tick 0, "no answer before the watchdog".)"""
from pathlib import Path

import numpy as np
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
from composed_sim.hosts.workers.worker_host import WorkerHost
from composed_sim.world.loader import load_world
from composed_sim.world.schema import NodeSpec
from tests.hosting.probes import probe_package

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "swarm_start"
SOURCE = '''
import math

from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Float32MultiArray, String


class LidarLayer(Node):
    def __init__(self):
        super().__init__('lidar_layer')
        self.range_max = self.declare_parameter('range_max', 0.5).value
        self.publisher = self.create_publisher(Float32MultiArray, self.get_namespace() + '/range_data', 10)
        self.create_subscription(LaserScan, self.get_namespace() + '/scan', self.on_scan, qos_profile_sensor_data)

    def on_scan(self, scan):
        best, bearing = self.range_max, 0.0
        for i, r in enumerate(scan.ranges):
            if math.isfinite(r) and r < best:
                best, bearing = r, scan.angle_min + i * scan.angle_increment
        self.publisher.publish(Float32MultiArray(data=[float(best), float(bearing)]))


class Dispersion(Node):
    def __init__(self):
        super().__init__('dispersion_pattern')
        self.speed = self.declare_parameter('max_translational_velocity', 0.1).value
        self.turn = self.declare_parameter('max_rotational_velocity', 1.0).value
        self.started = False
        self.create_subscription(String, '/swarm_command', self.on_command, 10)
        self.create_subscription(Float32MultiArray, self.get_namespace() + '/range_data', self.on_range,
                                 qos_profile_sensor_data)
        self.commands = self.create_publisher(Twist, self.get_namespace() + '/drive_command', 10)

    def on_command(self, msg):
        self.started = msg.data == 'start'

    def on_range(self, msg):
        if not self.started:
            return
        nearest, bearing = msg.data
        out = Twist()
        out.linear.x = self.speed
        out.angular.z = -self.turn * bearing if nearest < 0.3 else 0.0
        self.commands.publish(out)


class HardwareProtection(Node):
    def __init__(self):
        super().__init__('hardware_protection_layer')
        self.max_speed = self.declare_parameter('max_translational_velocity', 0.05).value
        self.too_close = False
        self.create_subscription(Twist, self.get_namespace() + '/drive_command', self.on_command, 10)
        self.create_subscription(Float32MultiArray, self.get_namespace() + '/range_data', self.on_range,
                                 qos_profile_sensor_data)
        self.cmd_vel = self.create_publisher(Twist, self.get_namespace() + '/cmd_vel', 10)

    def on_range(self, msg):
        self.too_close = msg.data[0] < 0.15

    def on_command(self, msg):
        if self.too_close:
            msg.linear.x = 0.0
        msg.linear.x = max(-self.max_speed, min(self.max_speed, msg.linear.x))
        self.cmd_vel.publish(msg)
        self.get_logger().info('cmd_vel')


class StartInConstructor(Node):
    def __init__(self):
        super().__init__('swarm_start')
        self.publisher = self.create_publisher(String, '/swarm_command', 10)
        self.publisher.publish(String(data='start'))


class StartOnTimer(Node):
    def __init__(self):
        super().__init__('swarm_start')
        self.publisher = self.create_publisher(String, '/swarm_command', 10)
        self.sent = False
        self.create_timer(0.1, self.on_timer)

    def on_timer(self):
        if not self.sent:
            self.publisher.publish(String(data='start'))
            self.sent = True
'''
PARAMS = """/**:
  ros__parameters:
    max_translational_velocity: 0.08
    max_rotational_velocity: 1.5
"""
FIRST_ANSWER = {"StartInConstructor": 0, "StartOnTimer": 1}     # the tick the start command reaches the robots


@pytest.fixture
def swarm_start(tmp_path, monkeypatch):
    (tmp_path / "params.yaml").write_text(PARAMS)
    for _ in probe_package(tmp_path, monkeypatch, PACKAGE, SOURCE):
        yield tmp_path / "params.yaml"


def world_of(start: str, params: Path):
    world = load_world(ROOT / "worlds" / "turtlebot_obstacles.yaml", robots=3, ticks=6, seed=7)
    nodes = [NodeSpec(node=f"{PACKAGE}:LidarLayer"),
             NodeSpec(node=f"{PACKAGE}:Dispersion", params_file=str(params)),
             NodeSpec(node=f"{PACKAGE}:HardwareProtection", params_file=str(params))]
    robots = world.robots[0].model_copy(update={"controller": None, "params": {}, "nodes": nodes})
    lockstep = world.lockstep.model_copy(update={"watchdog_s": 2.0})
    return world.model_copy(update={"robots": [robots], "nodes": [NodeSpec(node=f"{PACKAGE}:{start}")],
                                    "lockstep": lockstep})


HOSTS = {"workers 1": lambda world, domain, mp: ComposedHost(world, domain_id=domain),
         "workers 2": lambda world, domain, mp: WorkerHost(world, workers=2, domain_id=domain),
         "multi-process": lambda world, domain, mp: MultiProcessHost(world, domain_id=mp)}


@pytest.mark.parametrize("mode, start", [("workers 1", "StartInConstructor"), ("workers 1", "StartOnTimer"),
                                         ("workers 2", "StartOnTimer"), ("multi-process", "StartOnTimer")])
def test_a_chain_gated_on_a_run_wide_start_command_misses_no_tick(swarm_start, domain_id, mp_domain, tmp_path,
                                                                    mode, start):
    world = world_of(start, swarm_start)
    with HOSTS[mode](world, domain_id, mp_domain) as host:
        result = host.run()
    assert [v for v in result.violations if v.tick == 0] == []
    assert result.violations == []
    # Each robot drives from the start command on (its first cmd_vel acts a tick later).
    steps = np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2)
    assert (steps[FIRST_ANSWER[start] + 1:] > 1e-4).all(), steps
