"""Robots' ROS 2 programs as users write them for a process of their own
(tests/user_pkg/robot_programs): services called from callbacks (blocking in a reentrant group,
``async def`` + ``await``, done callbacks), actions with feedback and cancel, lifecycle nodes,
parameters set at run time by a run-wide node, calls between robots and run-wide nodes. Each is
hosted as its own process would run it, in every host mode and worker layout, with the same paths."""
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import importable
from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world
from composed_sim.world.schema import NodeSpec

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
PACKAGE = ROOT / "tests" / "user_pkg" / "robot_programs"
INTERFACES = ROOT / "tests" / "user_pkg" / "robot_programs_interfaces"


@pytest.fixture
def robot_programs(monkeypatch):
    yield from importable(monkeypatch, PACKAGE)


def world_of(*nodes: str, robots: int = 4, ticks: int = 30, run_wide: tuple = (), seed: int = 3, **group):
    """``robots`` foot-bots of the flocking arena, each running ``nodes`` (``module:Class``
    of robot_programs), and the ``run_wide`` nodes ((node, parameters) pairs)."""
    world = load_world(FLOCKING, robots=robots, ticks=ticks, seed=seed)
    base = world.robots[0]
    specs = [NodeSpec(node=f"robot_programs.{n}") for n in nodes]
    robots_group = base.model_copy(update={"count": robots, "controller": None, "params": {}, "nodes": specs, **group})
    return world.model_copy(update={
        "robots": [robots_group], "interfaces": [str(INTERFACES)],
        "nodes": [NodeSpec(node=f"robot_programs.{n}", parameters=p) for n, p in run_wide]})


def composed(world, domain_id, executor="lockstep"):
    """The run's result, and its nodes by class name (read after the run, before teardown)."""
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        result = host.run()
        nodes = {}
        for node in (*host.controllers, *(host.groups.run_wide.nodes if host.groups.run_wide else ())):
            nodes.setdefault(type(node).__name__, []).append(node)
        return result, nodes


def moved(result) -> np.ndarray:
    return np.linalg.norm(result.trajectories.positions[-1] - result.trajectories.positions[0], axis=1)


def path_length(result) -> np.ndarray:
    return np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2).sum(axis=0)


@pytest.mark.parametrize("behaviour", ["BlockingBehaviour", "AsyncBehaviour", "FutureBehaviour", "TutorialClient"])
def test_a_behaviour_node_calls_its_planner_in_each_way_and_drives_as_one_node_would(robot_programs, domain_id,
                                                                                    behaviour):
    reference, _ = composed(world_of("planning:FutureBehaviour", "planning:Planner"), domain_id)
    result, nodes = composed(world_of(f"planning:{behaviour}", "planning:Planner"), domain_id)
    assert result.violations == []
    assert (moved(result) > 0.03).all()
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert [p.calls for p in nodes["Planner"]] == [30] * 4       # one call per robot and tick, answered in it


def test_a_mission_node_drives_by_one_tick_goals_of_its_driver_node_with_feedback(robot_programs, domain_id):
    reference, _ = composed(world_of("planning:FutureBehaviour", "planning:Planner"), domain_id)
    result, nodes = composed(world_of("driving:AwaitingMission", "driving:QuickDriver"), domain_id)
    assert result.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert [(m.feedback, m.results) for m in nodes["AwaitingMission"]] == [(30, 30)] * 4


def test_goals_over_several_ticks_are_driven_on_the_robots_clock_and_cancelled_near_obstacles(robot_programs, domain_id):
    world = world_of("driving:Driver", "driving:Mission", robots=6, ticks=60, answers="when_published")
    result, nodes = composed(world, domain_id)
    again, _ = composed(world, domain_id)
    assert result.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, again.trajectories.positions)
    missions, drivers = nodes["Mission"], nodes["Driver"]
    free = [d.cancelled == 0 for d in drivers]
    assert 0 < sum(free) < len(free)                  # some robots start close to another: their goals are cancelled
    for mission, driver, alone, length in zip(missions, drivers, free, path_length(result)):
        if alone:       # 5-tick goals back to back, each tick fed back; its rate's first sleep ends at
                        # tick 1 (as rclpy's on sim time), so the 12th result comes after the run's end
            assert (driver.goals, mission.results, mission.feedback) == (12, 11, 60) and length > 0.25
        else:                                         # at most the last goal and a cancelled one still out
            assert 0 <= driver.goals - mission.results <= 2 and driver.cancelled > 0


def test_blocking_send_goal_and_get_result_in_a_reentrant_group(robot_programs, domain_id):
    result, nodes = composed(world_of("driving:Driver", "driving:BlockingMission", ticks=31,
                                      answers="when_published"), domain_id)
    assert result.violations == []
    assert [m.results for m in nodes["BlockingMission"]] == [[3] * 10] * 4   # a 3-tick goal, then the next


def test_robots_ask_a_run_wide_planner_and_are_answered_within_the_tick(robot_programs, domain_id):
    reference, _ = composed(world_of("planning:FutureBehaviour", "planning:Planner"), domain_id)
    result, nodes = composed(world_of("fleet:AsksTheFleet", run_wide=[("fleet:FleetPlanner", {})]), domain_id)
    assert result.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert nodes["FleetPlanner"][0].calls == 4 * 30


def test_a_run_wide_node_sets_each_robots_speed_parameter_through_its_parameter_services(robot_programs, domain_id):
    robots = [f"bot{i}" for i in range(4)]
    world = world_of("fleet:SpeedFollower", ticks=40, run_wide=[
        ("fleet:SpeedSetter", {"robots": robots, "speeds": [0.06, -1.0, 0.03], "period": 1.0})])
    result, nodes = composed(world, domain_id)
    assert result.violations == []
    setter = nodes["SpeedSetter"][0]
    # its 1 s timer, as rclpy's on sim time: tick 10: 0.06 taken; tick 20: -1.0 refused by the
    # node's own callback; tick 30: 0.03 taken
    assert setter.results == [[(True, "")]] * 4 + [[(False, "speed must not be negative")]] * 4 + [[(True, "")]] * 4
    assert [f.speed for f in nodes["SpeedFollower"]] == [0.03] * 4
    step = np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2)
    assert step[15:20].max() > step[35:40].max()                # faster at 0.06 m/s than at 0.03


def test_a_callback_that_sleeps_holds_its_mutually_exclusive_group_across_ticks(robot_programs, domain_id, mp_domain):
    """The nap's wake-up timer is not of the held group (as rclpy's rates have a group of their
    own), and the run-wide messages delivered meanwhile wait until the group is free."""
    world = world_of("groups:NapsInItsGroup", robots=2, ticks=38, run_wide=[("groups:Drummer", {})])
    result, nodes = composed(world, domain_id)
    in_own_processes = in_processes(world, mp_domain)
    assert result.violations == in_own_processes.violations == []
    np.testing.assert_array_equal(in_own_processes.trajectories.positions, result.trajectories.positions)
    assert (moved(result) > 0.05).all()
    for napper in nodes["NapsInItsGroup"]:
        assert len(napper.naps) >= 3
        assert all(0.35 <= round(end - start, 9) <= 0.4 for start, end in napper.naps), napper.naps  # the tick after
        assert napper.beats_while_napping == 0
        assert napper.beats >= 34                    # the ones delivered during a nap came after it


def lifecycle_world(node: str = "LifecycleBehaviour", lifecycle: str = "manual", manager: bool = False, **kw):
    world = world_of(**kw)
    group = world.robots[0]
    spec = NodeSpec(node=f"robot_programs.lifecycle:{node}", lifecycle=lifecycle)
    robots = [f"bot{i}" for i in range(group.count)]
    run_wide = [NodeSpec(node="robot_programs.lifecycle:LifecycleManager", parameters={"robots": robots})] \
        if manager else []
    return world.model_copy(update={"robots": [group.model_copy(update={"nodes": [spec]})], "nodes": run_wide})


@pytest.mark.parametrize("started", ["by the world file", "by itself", "by a lifecycle manager"])
def test_lifecycle_nodes_make_their_publisher_when_configured_and_answer_once_active(robot_programs, domain_id,
                                                                                  started):
    reference, _ = composed(world_of("planning:FutureBehaviour", "planning:Planner"), domain_id)
    world = {"by the world file": lifecycle_world(lifecycle="autostart"),
             "by itself": lifecycle_world("SelfStartingBehaviour"),
             "by a lifecycle manager": lifecycle_world(manager=True)}[started]
    result, nodes = composed(world, domain_id)
    assert result.violations == []
    behaviours = nodes.get("LifecycleBehaviour", []) + nodes.get("SelfStartingBehaviour", [])
    assert [b.transitions for b in behaviours] == [["configure", "activate"]] * 4
    if started != "by a lifecycle manager":
        np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
        return
    # The manager's 0.1 s timer brings them up at tick 1, as rclpy's on sim time: until then each
    # robot keeps its last command (none: it stands), with no violation; then it steers.
    assert nodes["LifecycleManager"][0].results == [True] * 8      # configure and activate, each robot
    positions = result.trajectories.positions
    assert np.array_equal(positions[1], positions[0]) and (moved(result) > 0.03).all()


def test_a_lifecycle_node_never_activated_keeps_its_robot_standing_and_is_named_at_start(robot_programs, domain_id,
                                                                                       capfd):
    """Another process could still activate it (its lifecycle services are there): the robot is
    not refused, it keeps its last command (none: it stands), as a robot's base does."""
    result, _ = composed(lifecycle_world(ticks=5), domain_id)
    assert result.violations == []
    assert (moved(result) == 0).all()
    assert "bot0, bot1, bot2, bot3 have no active cmd_vel publisher yet" in capfd.readouterr().err


def test_an_autostarted_lifecycle_node_publishing_on_another_robots_topic_is_refused_before_tick_0(robot_programs,
                                                                                                   domain_id):
    """What ``on_configure`` makes is checked against the topic contract as a constructor's is."""
    from composed_sim import plugins
    world = lifecycle_world(lifecycle="autostart", robots=2, ticks=3)
    group = world.robots[0]
    spec = group.nodes[0].model_copy(update={"parameters": {"cmd_topic": "/bot1/cmd_vel"}})
    world = world.model_copy(update={"robots": [group.model_copy(update={"nodes": [spec]})]})
    with pytest.raises(plugins.PluginError, match=r"^robots\[0\]\.nodes\[0\]: node .* for bot0: /bot1/cmd_vel is a "
                                                  r"topic of bot1, not of bot0$"):
        composed(world, domain_id)


def in_workers(world, domain_id, workers: int):
    from composed_sim.hosts.workers.worker_host import WorkerHost
    with WorkerHost(world, workers=workers, domain_id=domain_id) as host:
        return host.run()


PROGRAMS = {
    "blocking call": lambda: world_of("planning:BlockingBehaviour", "planning:Planner", robots=5, ticks=20),
    "awaited call": lambda: world_of("planning:AsyncBehaviour", "planning:Planner", robots=5, ticks=20),
    "run-wide planner": lambda: world_of("fleet:AsksTheFleet", robots=5, ticks=20,
                                         run_wide=[("fleet:FleetPlanner", {})]),
    "run-wide parameters": lambda: world_of("fleet:SpeedFollower", robots=5, ticks=25, run_wide=[
        ("fleet:SpeedSetter", {"robots": [f"bot{i}" for i in range(5)], "speeds": [0.06, -1.0, 0.03]})]),
    "lifecycle manager": lambda: lifecycle_world(manager=True, robots=5, ticks=20),
    "actions": lambda: world_of("driving:Driver", "driving:Mission", robots=5, ticks=30, answers="when_published"),
}


@pytest.mark.parametrize("program", PROGRAMS)
@pytest.mark.parametrize("workers", [2, pytest.param(3, marks=pytest.mark.slow)])    # the full matrix: -m slow
def test_each_program_runs_in_worker_processes_as_in_one(robot_programs, domain_id, program, workers):
    world = PROGRAMS[program]()
    reference, _ = composed(world, domain_id)
    result = in_workers(world, domain_id, workers)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


def in_processes(world, domain, executor: str = "lockstep"):
    from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
    with MultiProcessHost(world, domain_id=domain, robots_per_domain=2, executor=executor) as host:
        return host.run()


OWN_PROCESS = {    # a robot's nodes among themselves
    "blocking call": PROGRAMS["blocking call"],
    "awaited call": PROGRAMS["awaited call"],
    "one-tick goals": lambda: world_of("driving:AwaitingMission", "driving:QuickDriver", robots=3, ticks=15),
    "lifecycle autostart": lambda: lifecycle_world(lifecycle="autostart", robots=3, ticks=15),
}


@pytest.mark.parametrize("program", [p if p == "blocking call" else pytest.param(p, marks=pytest.mark.slow)
                                     for p in OWN_PROCESS])
def test_each_program_runs_in_processes_of_its_own_as_hosted(robot_programs, domain_id, mp_domain, program):
    world = OWN_PROCESS[program]()
    world = world.model_copy(update={"robots": [world.robots[0].model_copy(update={"count": 3})]})
    reference, _ = composed(world, domain_id)
    result = in_processes(world, mp_domain)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


BETWEEN_PLACES = {
    "run-wide planner": lambda: world_of("fleet:AsksTheFleet", robots=3, ticks=15,
                                         run_wide=[("fleet:FleetPlanner", {})]),
    "run-wide parameters": lambda: world_of("fleet:SpeedFollower", robots=3, ticks=25, run_wide=[
        ("fleet:SpeedSetter", {"robots": [f"bot{i}" for i in range(3)], "speeds": [0.06, -1.0, 0.03]})]),
}


@pytest.mark.parametrize("program", [p if p == "run-wide planner" else pytest.param(p, marks=pytest.mark.slow)
                                     for p in BETWEEN_PLACES])
def test_calls_between_robots_and_run_wide_nodes_in_processes_of_their_own(robot_programs, domain_id, mp_domain,
                                                                          program):
    world = BETWEEN_PLACES[program]()
    reference, _ = composed(world, domain_id)
    result = in_processes(world, mp_domain)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


def test_in_processes_of_their_own_lifecycle_nodes_a_manager_activates_later_run_as_in_one(robot_programs, domain_id,
                                                                                          mp_domain):
    """The same rule for when a robot must answer in every mode: a robot whose lifecycle node is
    not active when its process starts is waited for until it answers (docs/contract.md)."""
    world = lifecycle_world(manager=True, robots=2, ticks=8)
    reference, _ = composed(world, domain_id)
    result = in_processes(world, mp_domain)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


def test_a_node_that_spins_an_executor_of_its_own_is_named_before_tick_0(robot_programs, domain_id):
    from composed_sim.plugins import PluginError
    with pytest.raises(PluginError, match=r"robots\[0\]\.nodes\[0\]: node 'robot_programs\.planning:SpinsItself' for "
                                          r"bot0: its constructor adds it to an executor of its own "
                                          r"\(MultiThreadedExecutor\)"):
        composed(world_of("planning:SpinsItself", "planning:Planner", robots=2, ticks=3), domain_id)


def test_a_blocking_call_in_the_group_that_takes_its_response_fails_only_its_robot(robot_programs, domain_id):
    world = world_of("planning:SameGroupBehaviour", "planning:Planner", robots=2, ticks=5)
    base = world.robots[0].model_copy(update={"count": 2})
    others = world.robots[0].model_copy(update={"count": 2, "nodes": [NodeSpec(node="robot_programs.planning:FutureBehaviour"),
                                                                      NodeSpec(node="robot_programs.planning:Planner")]})
    result, _ = composed(world.model_copy(update={"robots": [base, others]}), domain_id)
    failed = {v.robot: v.reason for v in result.violations if "failed" in v.reason}
    assert set(failed) == {"bot0", "bot1"}                   # bot2 and bot3 (other nodes) drive on
    assert ("/bot0/behaviour waits for /bot0/plan (Client.call) in a callback of the mutually exclusive callback "
            "group that must also take its response: it would wait forever") in failed["bot0"]
    assert (moved(result)[2:] > 0.005).all()


PARAM_TOOL = """
import sys, rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.executors import SingleThreadedExecutor
domain, target, name, value = int(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4])
context = Context(); rclpy.init(context=context, domain_id=domain)
node = Node("param_tool", context=context)
client = AsyncParameterClient(node, target)
ready = client.wait_for_services(timeout_sec=60.0)
executor = SingleThreadedExecutor(context=context); executor.add_node(node)
def answer(future):
    executor.spin_until_future_complete(future, timeout_sec=30)
    return future.result()
listed = answer(client.list_parameters([], 1))
done = answer(client.set_parameters([Parameter(name, value=value)]))
got = answer(client.get_parameters([name]))
print(ready, name in listed.result.names, [r.successful for r in done.results], got.values[0].double_value, flush=True)
"""

OUTSIDE_TARGETS = {      # what the tool sets: (mode, node, parameter, value)
    "a robot's node": ("composed", "/bot0/behaviour", "speed", 0.0),
    "a robot's node in a process of its own": ("multi-process", "/bot0/behaviour", "speed", 0.0),
    "a run-wide node": ("composed", "/speed_setter", "period", 5.0),
    "a run-wide node beside processes of their own": ("multi-process", "/speed_setter", "period", 5.0),
}


@pytest.mark.parametrize("target", [t if t == "a robot's node" else pytest.param(t, marks=pytest.mark.slow)
                                    for t in OUTSIDE_TARGETS])
def test_another_process_sets_a_hosted_nodes_parameter_through_its_parameter_services(robot_programs, domain_id,
                                                                                     mp_domain, target):
    """As ``ros2 param set`` would: the node's parameter services get their DDS endpoints once a
    client of another process is on the ROS graph; its requests are served as a tick starts."""
    import subprocess
    from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
    mode, node, name, value = OUTSIDE_TARGETS[target]
    world = world_of("fleet:SpeedFollower", robots=2, ticks=1_000_000,     # until the tool is done
                     run_wide=[("fleet:SpeedSetter", {"robots": ["bot1"], "speeds": [0.02]})])
    domain = domain_id if mode == "composed" else mp_domain
    host = ComposedHost(world, domain_id=domain) if mode == "composed" else \
        MultiProcessHost(world, domain_id=domain, robots_per_domain=2)
    with host:      # the tool started once the host is set up, as a user runs ``ros2 param set``
        tool = subprocess.Popen([sys.executable, "-c", PARAM_TOOL, str(domain), node, name, str(value)],
                                stdout=subprocess.PIPE, text=True)
        try:
            result = host.run(should_stop=lambda: tool.poll() is not None)
        finally:
            out, _ = tool.communicate(timeout=60)
    assert out.split() == ["True", "True", "[True]", str(value)], out
    assert result.violations == []
    steps = np.linalg.norm(np.diff(result.trajectories.positions, axis=0), axis=2)
    if name == "speed":
        assert steps[-1, 0] < 1e-6 < steps[-1, 1]           # bot0 stopped; bot1 drives on
    else:
        assert (steps[-1] > 1e-6).all()


def run_in_processes_of_their_own(world, domain_id, tmp_path, processes, observers=()):
    """``world``'s robots driven by their nodes in a process per robot, started by rclpy alone
    (tests/hosts/outside/controllers_of_their_own.py, under rclpy's multi-threaded executor, as the
    blocking calls' authors must), through ``run --external-controllers``: the result."""
    import os
    from tests.conftest import start
    from tests.hosts.outside.controllers_of_their_own import command
    from composed_sim.hosts.outside_controllers import OutsideControllersHost
    from composed_sim.world.loader import dump_world
    path = tmp_path / "world.yaml"
    path.write_text(dump_world(world))
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    for i in range(world.robot_count):
        processes.append(start(command(path, world.robot_count, world.seed, i, threads=True), tmp_path / f"bot{i}.log",
                               env))
    with OutsideControllersHost(world.model_copy(update={"nodes": []}), domain_id=domain_id,
                                discovery_timeout_s=60.0) as host:
        return host.run(observers=observers)


@pytest.mark.parametrize("behaviour", ["BlockingBehaviour", "AsyncBehaviour"])
def test_a_robots_service_calls_in_processes_of_their_own_drive_the_run_as_hosted(robot_programs, domain_id, tmp_path,
                                                                                 processes, behaviour):
    """The ground truth of hosting: each robot's behaviour and planner in a process of its own,
    under rclpy's own executor; the hosted run's trajectories are theirs, bit for bit."""
    world = world_of(f"planning:{behaviour}", "planning:Planner", robots=3, ticks=15)
    reference, _ = composed(world, domain_id)
    result = run_in_processes_of_their_own(world, domain_id, tmp_path, processes)
    assert result.violations == [], (tmp_path / "bot0.log").read_text()[-2000:]
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert (moved(reference) > 0.01).all()


@pytest.mark.slow      # wall-clock paced: under the loaded default run a process of its own lost a goal
@pytest.mark.parametrize("mission", ["Mission", "BlockingMission"])
def test_a_robots_action_between_its_nodes_drives_as_far_as_in_processes_of_their_own(robot_programs, domain_id,
                                                                                      tmp_path, processes, mission):
    """A mission node sends its driver node 5-tick goals, the robot driving while each runs. In
    processes of their own, under rclpy's executor and its sim-time sleeps, the goals' handshakes
    take DDS round trips between ticks, so the robots answer when published and the run is paced
    at real time; each robot's path is the hosted one's within a centimetre (measured: equal to
    the millimetre, 0.194 m in 40 ticks, in either mission)."""
    from composed_sim.live.pacing import Pacer
    world = world_of(f"driving:{mission}", "driving:Driver", robots=3, ticks=40, answers="when_published")
    reference, _ = composed(world, domain_id)
    result = run_in_processes_of_their_own(world, domain_id, tmp_path, processes,
                                           observers=[Pacer(1.0, world.tick_s)])
    assert result.violations == [], (tmp_path / "bot0.log").read_text()[-2000:]
    assert (path_length(reference) > 0.1).all()
    np.testing.assert_allclose(path_length(result), path_length(reference), atol=0.01)


STOCK = ("single-threaded", "events", "multi-threaded")


@pytest.mark.parametrize("executor", STOCK)
@pytest.mark.parametrize("program", ["awaited call", "done callback", *(
    pytest.param(p, marks=pytest.mark.slow) for p in ("one-tick goals", "lifecycle autostart", "run-wide planner"))])
def test_rclpys_own_executors_host_what_they_run_in_a_process_of_their_own(robot_programs, domain_id, executor,
                                                                           program):
    """rclpy's executors, kept for comparison, host each program their threading allows, as the
    default executor does."""
    world = {"awaited call": lambda: world_of("planning:AsyncBehaviour", "planning:Planner", robots=3, ticks=12),
             "done callback": lambda: world_of("planning:FutureBehaviour", "planning:Planner", robots=3, ticks=12),
             "one-tick goals": lambda: world_of("driving:AwaitingMission", "driving:QuickDriver", robots=3, ticks=12),
             "lifecycle autostart": lambda: lifecycle_world(lifecycle="autostart", robots=3, ticks=12),
             "run-wide planner": lambda: world_of("fleet:AsksTheFleet", robots=3, ticks=12,
                                                  run_wide=[("fleet:FleetPlanner", {})])}[program]()
    reference, _ = composed(world, domain_id)
    if executor == "multi-threaded" and program == "run-wide planner":
        multi_threaded_warns(world, domain_id)
    if executor == "events" and program in ("awaited call", "one-tick goals"):
        from composed_sim.hosting import HostError
        with pytest.raises(HostError, match=r"/bot0/\w+ has an async def callback .*: rclpy's EventsExecutor never "
                                            r"awaits it \(in a process of its own too\)"):
            composed(world, domain_id, executor)
        return
    result, _ = composed(world, domain_id, executor)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)


@pytest.mark.parametrize("executor", ["lockstep", "single-threaded"])
def test_a_client_made_after_construction_does_not_find_a_service_nobody_serves(robot_programs, domain_id, executor):
    """While the nodes are built, a client's wait for a service the host will serve ends at once;
    later, it is rclpy's own wait."""
    result, nodes = composed(world_of("planning:LateLookup", robots=2, ticks=2), domain_id, executor)
    assert result.violations == []
    assert [n.found for n in nodes["LateLookup"]] == [False, False]


def multi_threaded_warns(world, domain_id):
    import contextlib
    import io
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        with ComposedHost(world, executor="multi-threaded", domain_id=domain_id):
            pass
    assert "in worker processes a call to a run-wide node made after the tick's rounds completes as the next " \
           "tick opens" in err.getvalue()


def test_a_blocking_call_runs_on_rclpys_multi_threaded_executor_and_is_refused_by_one_thread(robot_programs,
                                                                                             domain_id):
    # rclpy's executor blocks one of its threads on the call, as in the robot's own process.
    one = world_of("planning:BlockingBehaviour", "planning:Planner", robots=1, ticks=8)
    reference, _ = composed(one, domain_id)
    threaded, _ = composed(one, domain_id, "multi-threaded")
    assert threaded.violations == []
    np.testing.assert_array_equal(threaded.trajectories.positions, reference.trajectories.positions)
    world = world_of("planning:BlockingBehaviour", "planning:Planner", robots=2, ticks=8)
    single, _ = composed(world, domain_id, "single-threaded")
    failed = [v for v in single.violations if "failed" in v.reason]
    assert {v.robot for v in failed} == {"bot0", "bot1"}
    assert "which runs one callback at a time: it would wait forever, in its own process too" in failed[0].reason
