"""Nodes as ROS users write them, hosted as they are (tests/plugin_pkg/ros_styles.py): unstamped
Twist, timer-driven decisions on sim time, sensor-data QoS; mixed in one world, in every executor
and in both host modes."""
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from composed_sim import plugins
from composed_sim.hosting.process_hosting import EXECUTORS
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
from composed_sim.hosts.workers.worker_host import WorkerHost
from composed_sim.world.loader import load_world
from composed_sim.world.schema import Lockstep

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
sys.path.insert(0, str(ROOT / "tests"))
from conftest import install_plugin  # noqa: E402 - after tests/ is put on sys.path

STYLES = {"twist-on-scan": "TwistOnScan", "stamped-timer": "StampedTimer", "twist-timer": "TwistTimer",
          "unstamped-timer": "UnstampedTimer",
          "no-options": "NoOptions", "string-commands": "StringCommands", "wrong-sensor": "WrongSensor",
          "no-answer": "NoAnswer", "every-third-tick": "EveryThirdTick", "asks-the-planner": "AsksThePlanner",
          "planner": "Planner"}


@pytest.fixture
def styles(tmp_path, monkeypatch):
    install_plugin(tmp_path, monkeypatch, "ros_styles", STYLES)
    yield
    sys.modules.pop("ros_styles", None)


def mixed_world(ticks=30, seed=3, **extra_groups):
    """Two robots of each style, side by side in the flocking arena."""
    world = load_world(FLOCKING, robots=6, ticks=ticks, seed=seed)
    base = world.robots[0]
    groups = [base.model_copy(update={"count": 2, "controller": name, "params": {}})
              for name in ("twist-on-scan", "stamped-timer", "twist-timer")]
    return world.model_copy(update={"robots": groups})


def composed(world, domain_id, executor="lockstep"):
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        return host.run()


def test_mixed_styles_answer_every_tick_in_every_executor_bit_identically(styles, domain_id):
    world = mixed_world()
    results = {ex: composed(world, domain_id, ex) for ex in EXECUTORS}
    reference = results["lockstep"]
    moved = np.linalg.norm(reference.trajectories.positions[-1] - reference.trajectories.positions[0], axis=1)
    assert (moved > 0.03).all(), moved           # every style drove its robot
    for executor, result in results.items():
        assert result.violations == [], (executor, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions,
                                      err_msg=executor)


def test_mixed_styles_run_alike_in_multi_process_mode_and_in_workers(styles, domain_id, mp_domain):
    world = mixed_world(ticks=25)
    reference = composed(world, domain_id)
    for host in (MultiProcessHost(world, domain_id=mp_domain, robots_per_domain=3),
                 WorkerHost(world, workers=2, domain_id=domain_id)):
        with host:
            result = host.run()
        assert result.violations == [], (type(host).__name__, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


def test_best_effort_subscriber_receives_every_tick_and_timers_fire_once_per_tick(styles, domain_id):
    world = mixed_world(ticks=20)
    with ComposedHost(world, executor="single-threaded", domain_id=domain_id) as host:
        result = host.run()
        readings = [n.readings for n in host.controllers if type(n).__name__ == "TwistOnScan"]
        decisions = [n.decisions for n in host.controllers if type(n).__name__ == "TwistTimer"]
    assert result.violations == []
    assert readings == [20, 20]          # best effort (qos_profile_sensor_data): no tick lost
    assert decisions == [19, 19]         # a 0.1 s timer on a 10 Hz world: ticks 1 … 19, as rclpy's on sim time


def with_timer(world, period, **group):
    g = world.robots[0].model_copy(update={"count": 3, "controller": "twist-timer",
                                           "params": {"period": period}, **group})
    return world.model_copy(update={"robots": [g]})


def test_timer_slower_than_the_tick_answers_every_kth_tick_without_violations(styles, domain_id, capfd):
    world = with_timer(load_world(FLOCKING, robots=3, ticks=20, seed=2), 0.2, answers_every_ticks=2)
    with ComposedHost(world, executor="lockstep", domain_id=domain_id) as host:
        result = host.run()
        assert [n.decisions for n in host.controllers] == [9, 9, 9]        # ticks 2, 4 … 18
    assert result.violations == []
    # From its first answer (tick 2) on, each robot kept its last command in between: it moved every tick.
    step = np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2)
    assert (step[2:] > 0).all()
    # Not declared: each tick in between is a violation, and the set-up said why.
    # (A short watchdog: each of those ticks waits for it.)
    undeclared = with_timer(load_world(FLOCKING, robots=3, ticks=6, seed=2), 0.2)
    undeclared = undeclared.model_copy(update={"lockstep": Lockstep(watchdog_s=2.0)})
    result = composed(undeclared, domain_id)
    # (ticks 0 and 1 come before its timer first fires: it had no chance to answer them)
    assert sorted({v.tick for v in result.violations}) == [3, 5]
    assert "set answers_every_ticks: 2" in capfd.readouterr().err


def test_timer_faster_than_the_tick_fires_once_per_tick_and_odd_periods_are_warned(styles, domain_id, capfd):
    world = with_timer(load_world(FLOCKING, robots=3, ticks=10, seed=2), 0.05)
    with ComposedHost(world, executor="lockstep", domain_id=domain_id) as host:
        result = host.run()
        assert [n.decisions for n in host.controllers] == [9, 9, 9]        # ticks 1 … 9
    assert result.violations == []
    odd = with_timer(load_world(FLOCKING, robots=3, ticks=3, seed=2), 0.15)
    # (A short watchdog: its ticks without an answer wait for it.)
    composed(odd.model_copy(update={"lockstep": Lockstep(watchdog_s=2.0)}), domain_id)
    assert "has a timer of 0.15 s, neither a multiple nor a divisor of the world's tick (0.1 s)" in capfd.readouterr().err


def one_group_model(fields):
    """A robot group's fields validated as the world file's (devices as settings objects)."""
    from composed_sim.world.schema import RobotGroup
    group = RobotGroup.model_validate({"controller": "x", "count": 1, **fields})
    return {k: getattr(group, k) for k in fields}


def one_group(controller, **group):
    world = load_world(FLOCKING, robots=2, ticks=3)
    return world.model_copy(update={"robots": [world.robots[0].model_copy(
        update={"controller": controller, "params": {}, **group})]})


def test_a_tutorial_node_without_node_options_is_hosted_in_every_mode(styles, domain_id, mp_domain):
    # __init__(self) with super().__init__('no_options'): the host hands Node.__init__ the robot's
    # namespace and context, so it answers on /botN/cmd_vel like a node taking **kwargs.
    world = one_group("no-options")
    reference = composed(world, domain_id)
    assert reference.violations == []
    assert (np.abs(np.diff(reference.trajectories.positions, axis=0)) > 0).any()
    for host in (MultiProcessHost(world, domain_id=mp_domain), WorkerHost(world, workers=2, domain_id=domain_id)):
        with host:
            result = host.run()
        assert result.violations == [], (type(host).__name__, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


def test_a_wrong_topic_fails_at_once_naming_what_the_robot_has(styles, domain_id):
    turtlebots = {"model": "turtlebot3-burger", "devices": {"lidar": {"enabled": True}}}
    started = time.monotonic()
    with pytest.raises(plugins.PluginError, match=r"robots\[0\]\.controller: controller plugin 'wrong-sensor' for "
                                                  r"bot0: node /bot0/wrong_sensor subscribes to /bot0/proximity, which "
                                                  r"bot0 does not have \(its sensor topics: /bot0/scan\); did you mean scan\?"):
        composed(one_group("wrong-sensor", **one_group_model(turtlebots)), domain_id)
    with pytest.raises(plugins.PluginError, match=r"none of bot0's nodes publishes /bot0/cmd_vel, the robot's answer "
                                                  r"to each tick \(they publish: .*/bot0/cmd_vel_out.*\); remap "
                                                  r"/bot0/cmd_vel_out to cmd_vel\?"):
        composed(one_group("no-answer"), domain_id)
    assert time.monotonic() - started < 30      # not the 60 s discovery timeout


def test_wrong_cmd_vel_types_are_one_error_naming_robot_topic_and_types(styles, domain_id, mp_domain):
    accepted = r"geometry_msgs/msg/TwistStamped or geometry_msgs/msg/Twist"
    with pytest.raises(plugins.PluginError, match=rf"bot0: /bot0/cmd_vel carries {accepted} \(the topic contract\), "
                                                  r"not std_msgs/msg/String"):
        composed(one_group("string-commands"), domain_id)
    with pytest.raises(plugins.PluginError, match=r"publishes geometry_msgs/msg/Twist on /bot0/cmd_vel, but the world "
                                                  r"file says cmd_vel: stamped"):
        composed(one_group("twist-on-scan", cmd_vel="stamped"), domain_id)


def test_wrong_cmd_vel_type_in_multi_process_mode_is_the_same_one_error(styles, mp_domain):
    # Both robots' processes fail alike; whichever is first is reported, as the one process's error.
    with pytest.raises(plugins.PluginError, match=r"(bot\d): /\1/cmd_vel carries geometry_msgs/msg/TwistStamped or "
                                        r"geometry_msgs/msg/Twist \(the topic contract\), not std_msgs/msg/String"):
        with MultiProcessHost(one_group("string-commands"), domain_id=mp_domain) as host:
            host.run()


def test_a_robot_that_answers_when_published_keeps_its_last_command_in_every_mode(styles, domain_id, mp_domain):
    # cmd_vel on ticks 0, 3, 6 …: in between the tick closes once the robot's nodes are idle (not
    # at the watchdog), with no violation, and the robot goes on with its last command.
    world = one_group("every-third-tick", count=3, answers="when_published")
    world = world.model_copy(update={"length_ticks": 12})
    runs = {}
    for executor in EXECUTORS:
        runs[executor] = composed(world, domain_id, executor)
    for host in (WorkerHost(world, workers=2, domain_id=domain_id), MultiProcessHost(world, domain_id=mp_domain)):
        with host:
            runs[type(host).__name__] = host.run()
    reference = runs["lockstep"]
    step = np.linalg.norm(np.diff(reference.trajectories.positions, axis=0), axis=2)
    # the first step applies the initial zero command (ARGoS's tick order); then moving on every
    # tick, commands or none
    assert (step[0] == 0).all() and (step[1:] > 0.003).all()
    for name, result in runs.items():
        assert result.violations == [], (name, result.violations[:3])     # never the watchdog
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions, err_msg=name)


def test_a_service_between_a_robots_own_nodes_answers_within_the_tick(styles, domain_id, mp_domain):
    # The robot's answer comes from a service response: the request and the response are handled
    # inside the tick, the same in every executor and mode.
    from composed_sim.world.schema import NodeSpec
    world = one_group(None, count=3, nodes=[NodeSpec(node="asks-the-planner"), NodeSpec(node="planner")])
    world = world.model_copy(update={"length_ticks": 12})
    runs = {executor: composed(world, domain_id, executor) for executor in EXECUTORS}
    for host in (WorkerHost(world, workers=2, domain_id=domain_id), MultiProcessHost(world, domain_id=mp_domain)):
        with host:
            runs[type(host).__name__] = host.run()
    reference = runs["lockstep"]
    turning = np.diff(reference.trajectories.headings, axis=0)
    # the planner's rates: -0.2 rad/s on ticks 0-2, 0 on ticks 3-6 (tick 3 still turns a little: the body
    # follows its wheels through joints); tick 0's answer drives nothing (the first step applies the
    # initial zero command, as ARGoS's)
    assert (turning[0] == 0).all() and (np.abs(turning[1:3]) > 1e-2).all() and (np.abs(turning[4:7]) < 1e-9).all()
    for name, result in runs.items():
        assert result.violations == [], (name, result.violations[:3])
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions, err_msg=name)


@pytest.mark.parametrize("mode", ["composed", pytest.param("multi-process", marks=pytest.mark.slow)])
def test_a_twist_stamped_left_unstamped_answers_as_a_twist_does(styles, domain_id, mp_domain, mode):
    """A zero stamp is ROS's unset time, not a late answer to tick 0: such a TwistStamped is matched
    to a tick by its arrival, as a Twist is (it was dropped as an answer to tick 0, and the robots
    stood, booked as missing every tick after the first)."""
    world = load_world(FLOCKING, robots=4, ticks=30, seed=3)

    def run(style):
        group = world.robots[0].model_copy(update={"controller": style, "params": {}})
        w = world.model_copy(update={"robots": [group]})
        host = ComposedHost(w, domain_id=domain_id) if mode == "composed" else \
            MultiProcessHost(w, domain_id=mp_domain)
        with host:
            return host.run()

    unstamped, twist = run("unstamped-timer"), run("twist-timer")
    assert unstamped.violations == [] and twist.violations == []
    np.testing.assert_array_equal(unstamped.trajectories.positions, twist.trajectories.positions)
