"""Robots driven from outside the run (`run --external-controllers`): controllers started by a
program of their own with rclpy alone (controllers_of_their_own.py), in other processes, on one
machine and across network namespaces joined by a bridge (separate network stacks, as separate
machines would be). The ground truth is the same controllers hosted in one process."""
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import network_namespaces, start
from tests.hosts.outside.controllers_of_their_own import command
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosting import HostError
from composed_sim.hosts.discovery import DiscoveryError, configure
from composed_sim.hosts.outside_controllers import GONE_REASON, OutsideControllersHost
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[3]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
ROBOTS, TICKS, SEED = 12, 60, 3


def test_discovery_defaults_to_subnet_and_keeps_what_the_user_set():
    env = {}
    assert configure(environ=env) == ("SUBNET", None) and env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    description, warning = configure(environ=env)
    assert description == "LOCALHOST" and "only controllers on this machine" in warning
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}
    description, warning = configure(discovery_range="subnet", static_peers="10.0.0.2;10.0.0.3", environ=env)
    assert description == "SUBNET + static peers 10.0.0.2;10.0.0.3" and warning is None
    assert env == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.2;10.0.0.3"}
    with pytest.raises(DiscoveryError, match="--static-peers"):
        configure(static_peers=" ; ", environ={})


def world(robots=ROBOTS, ticks=TICKS, seed=SEED, watchdog_s=None):
    w = load_world(FLOCKING, robots=robots, ticks=ticks, seed=seed)
    if watchdog_s is not None:
        w = w.model_copy(update={"lockstep": w.lockstep.model_copy(update={"watchdog_s": watchdog_s})})
    return w


def of_their_own(robot: int, *, n=ROBOTS, seed=SEED) -> list[str]:
    """The command that starts the flocking world's robot ``robot`` in a process of its own."""
    return command(FLOCKING, n, seed, robot)


def start_robots(robots, tmp_path, processes, env, **kwargs) -> list:
    """Each of ``robots`` in a process of its own; returns them."""
    started = [start(of_their_own(i, **kwargs), tmp_path / f"bot{i}.log", env) for i in robots]
    processes += started
    return started


def wait_until_spinning(tmp_path, robots, processes) -> None:
    deadline = time.monotonic() + 120
    for i, p in zip(robots, processes):
        log = tmp_path / f"bot{i}.log"
        while "spinning" not in log.read_text():
            assert p.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)


# --- through real DDS, one machine --------------------------------------------------------------

def test_controllers_of_their_own_drive_the_run_as_the_same_nodes_hosted_do(tmp_path, processes, domain_id):
    # A program of rclpy's own per robot, half started before the simulator, half while it waits:
    # each robot is whatever publishes its cmd_vel, nothing announced.
    with ComposedHost(world(), domain_id=domain_id) as host:
        reference = host.run()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    wait_until_spinning(tmp_path, range(6), start_robots(range(6), tmp_path, processes, env))
    start_robots(range(6, ROBOTS), tmp_path, processes, env)
    with OutsideControllersHost(world(), domain_id=domain_id, discovery_timeout_s=60) as host:
        assert host.sim_node.answer_subscription("bot0") is not None
        result = host.run()
    assert result.violations == []
    for field in ("positions", "headings", "led_colors"):
        np.testing.assert_array_equal(getattr(result.trajectories, field), getattr(reference.trajectories, field))
    assert np.ptp(reference.trajectories.positions[:, :, 0], axis=0).max() > 0.01    # they moved


def test_a_robot_with_no_controller_is_a_clear_error_naming_it(tmp_path, processes, domain_id):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    wait_until_spinning(tmp_path, range(2), start_robots(range(2), tmp_path, processes, env, n=4))
    with pytest.raises(HostError, match=r"no controller connected for bot2, bot3 after 4 s \(seen: bot2: no cmd_vel "
                                        r"publisher, .*ROS domain \d+ that publishes /<robot>/cmd_vel"):
        with OutsideControllersHost(world(robots=4), domain_id=domain_id, discovery_timeout_s=4.0):
            pass


def test_two_controllers_of_one_robot_are_refused(tmp_path, processes, domain_id):
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    first = start_robots(range(2), tmp_path, processes, env, n=2)
    second = [start(of_their_own(1, n=2), tmp_path / "again.log", env)]
    processes += second
    wait_until_spinning(tmp_path, range(2), first)
    while "spinning" not in (tmp_path / "again.log").read_text():
        assert second[0].poll() is None, (tmp_path / "again.log").read_text()
        time.sleep(0.1)
    with pytest.raises(HostError, match=r"bot1 have more than one cmd_vel publisher"):
        with OutsideControllersHost(world(robots=2), domain_id=domain_id, discovery_timeout_s=30):
            pass


def test_a_world_with_run_wide_nodes_is_refused_at_once():
    w = world(robots=2)
    w = w.model_copy(update={"nodes": [w.robots[0].node_specs[0]]})
    with pytest.raises(HostError, match=r"run-wide nodes \(nodes:\) would be started by no one"):
        OutsideControllersHost(w)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_controller_that_disappears_turns_into_violations_for_its_robots(tmp_path, processes, sig, domain_id):
    # A watchdog that the first cross-process tick (one-off transport set-up) meets on a loaded machine.
    w = world(robots=4, ticks=30, watchdog_s=1.0)
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    start_robots(range(2), tmp_path, processes, env, n=4)
    victims = start_robots(range(2, 4), tmp_path, processes, env, n=4)
    kill_at = 10
    done = []

    def progress(n):
        done.append(n)
        if len(done) == kill_at:
            for victim in victims:
                victim.send_signal(sig)
            for victim in victims:      # rclpy's SIGTERM handler ends its spin; DDS's teardown may take
                victim.wait(timeout=60)     # seconds on a loaded machine (once over 10 s in a -n 2 run)

    t0 = time.perf_counter()
    with OutsideControllersHost(w, domain_id=domain_id, discovery_timeout_s=60) as host:
        result = host.run(progress=progress)
    wall = time.perf_counter() - t0
    assert result.trajectories.ticks_done == 30 and not result.interrupted
    assert result.violations and {v.robot for v in result.violations} == {"bot2", "bot3"}
    assert min(v.tick for v in result.violations) >= kill_at
    if sig == signal.SIGTERM:
        # rclpy's own program ends on SIGTERM and DDS removes its endpoints as it exits: one
        # violation per robot, nothing after it (on a loaded machine the exit may take longer than
        # the 1 s watchdog: a missed tick before it).
        gone = sorted((v.robot, v.reason) for v in result.violations if v.reason.startswith("controller failed"))
        assert gone == [("bot2", f"controller failed: {GONE_REASON}"), ("bot3", f"controller failed: {GONE_REASON}")]
        for robot in ("bot2", "bot3"):
            ticks = [v.tick for v in result.violations if v.robot == robot]
            reasons = [v.reason for v in result.violations if v.robot == robot]
            assert reasons[-1] == f"controller failed: {GONE_REASON}" and set(reasons[:-1]) <= {
                "no answer before the watchdog"} and ticks[-1] - ticks[0] <= 2, result.violations
    else:
        # Killed outright: DDS learns it only when the participant's lease runs out (Fast DDS: 20 s);
        # the watchdog closes each tick without them until they are unresponsive for 3 watchdogs.
        reasons = [v.reason for v in result.violations]
        assert set(reasons) - {"no answer before the watchdog"} <= {
            f"controller failed: {GONE_REASON}", *(r for r in reasons if r.startswith("controller failed: unresponsive"))}
        assert sum(r.startswith("controller failed") for r in reasons) == 2
        assert wall < 30 * 1.0 + 30
    # Fallback zero: the lost robots stand still from the tick after; the others drive on.
    pos = result.trajectories.positions
    first = min(v.tick for v in result.violations)
    lost = pos[first + 1:, 2:4]
    assert np.abs(lost - lost[0]).max() < 1e-3
    assert np.linalg.norm(pos[-1, :2] - pos[first + 1, :2], axis=1).min() > 0.005


# --- across network namespaces -------------------------------------------------------------------

@pytest.fixture
def netns():
    yield from network_namespaces(["sim", "s0", "s1"])


def test_controllers_in_other_network_namespaces_match_the_composed_run_bit_for_bit(tmp_path, netns, domain_id,
                                                                                   processes):
    with ComposedHost(world(), domain_id=domain_id) as host:
        reference = host.run()
    # Real UDP between the namespaces: SUBNET discovery (multicast), and no shared-memory transport,
    # which Fast DDS would otherwise pick between processes of one machine.
    env = {**os.environ, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", "ROS_DOMAIN_ID": str(domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    out = tmp_path / "out"
    processes += [start(netns.exec(f"s{i // 6}", of_their_own(i)), tmp_path / f"bot{i}.log", env) for i in range(ROBOTS)]
    sim = start(netns.exec("sim", [sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING),
                                   "--robots", str(ROBOTS), "--ticks", str(TICKS), "--seed", str(SEED),
                                   "--external-controllers", "--discovery-timeout", "60", "--discovery-range",
                                   "subnet", "--out", str(out), "--no-picture", "--no-progress"]),
                tmp_path / "sim.log", env)
    processes.append(sim)
    assert sim.wait(timeout=120) == 0, (tmp_path / "sim.log").read_text()
    # The traffic went through the veth links, not around them.
    assert all(netns.counters(role)["rx_bytes"] > 10_000 for role in ("sim", "s0", "s1"))
    with np.load(out / "trajectories.npz") as got:
        assert np.array_equal(got["positions"], reference.trajectories.positions)
        assert np.array_equal(got["headings"], reference.trajectories.headings)
        assert np.array_equal(got["led_colors"], reference.trajectories.led_colors)
    assert (out / "violations.csv").read_text().strip() == "tick,robot,reason"
    assert np.ptp(reference.trajectories.positions[:, :, 0], axis=0).max() > 0.01    # they moved


# A program of its own that drives on a wall-clock timer, as a vendor's example does (time.sleep,
# a timer of its own): its commands arrive whenever they arrive, also between two ticks.
DRIVES_ON_ITS_OWN_TIMER = """
import rclpy
from geometry_msgs.msg import Twist
rclpy.init(args=["--ros-args", "-r", "__ns:=/bot0"])
node = rclpy.create_node("drives_on_its_own_timer")
cmd = node.create_publisher(Twist, "cmd_vel", 10)
command = Twist()
command.linear.x = 0.1
node.create_timer(0.25, lambda: cmd.publish(command))
print("spinning", flush=True)
rclpy.spin(node)
"""


def test_a_robot_that_answers_when_published_keeps_a_command_that_came_between_two_ticks(tmp_path, processes,
                                                                                        domain_id):
    # At twice real time the simulator spends most of each tick waiting for the next; a command
    # that lands then is the robot's from the next tick on (it was dropped: the robot never moved).
    from composed_sim.live.pacing import Pacer
    w = world(robots=1, ticks=40)
    w = w.model_copy(update={"robots": [w.robots[0].model_copy(update={"answers": "when_published"})]})
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    processes.append(start([sys.executable, "-c", DRIVES_ON_ITS_OWN_TIMER], tmp_path / "bot0.log", env))
    wait_until_spinning(tmp_path, [0], processes)
    with OutsideControllersHost(w, domain_id=domain_id, discovery_timeout_s=60) as host:
        result = host.run(observers=[Pacer(2.0, w.tick_s)])
    assert result.violations == []
    steps = np.linalg.norm(np.diff(result.trajectories.positions[:, 0], axis=0), axis=1)
    moving = np.flatnonzero(steps > 0.004)          # 0.1 m/s over a 0.1 s tick: 0.01 m
    assert len(moving) and (steps[moving[0] + 1:] > 0.004).all(), np.round(steps, 4)


def test_a_robot_that_answers_when_published_is_failed_once_its_controller_is_gone(tmp_path, processes, domain_id):
    # Never waited for, such a robot's lost controller shows as no late answer: the graph says it
    # (it once drove on its last command with no violation, its process long dead).
    from composed_sim.live.pacing import Pacer
    w = world(robots=1, ticks=100)
    w = w.model_copy(update={"robots": [w.robots[0].model_copy(update={"answers": "when_published"})]})
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    controller = start([sys.executable, "-c", DRIVES_ON_ITS_OWN_TIMER], tmp_path / "bot0.log", env)
    processes.append(controller)
    wait_until_spinning(tmp_path, [0], processes)
    calls, stopped_at = [], []

    def progress(n):
        calls.append(n)
        if len(calls) == 10:
            controller.send_signal(signal.SIGTERM)
            controller.wait(timeout=60)
            stopped_at.append(len(calls))

    with OutsideControllersHost(w, domain_id=domain_id, discovery_timeout_s=60) as host:
        result = host.run(progress=progress, observers=[Pacer(2.0, w.tick_s)])
    assert stopped_at and [(v.robot, v.reason) for v in result.violations] == [
        ("bot0", f"controller failed: {GONE_REASON}")]
    failed_at = result.violations[0].tick
    assert 10 <= failed_at < 100
    pos = result.trajectories.positions[failed_at + 1:, 0]
    assert np.abs(pos - pos[0]).max() < 1e-9          # the fallback: it stands from then on
