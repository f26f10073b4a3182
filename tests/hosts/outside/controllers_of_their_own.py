"""A robot's nodes started as their authors start them, outside any run: one process per robot,
``rclpy.init`` given the robot's namespace, parameters and remappings as ``--ros-args`` (as
``ros2 run pkg node --ros-args -r __ns:=/bot3 -p use_sim_time:=true -p …`` gives them), each node built by its own
constructor, one executor of rclpy's, ``spin`` until stopped. No host of composed_sim's: it is
what drives ``run --external-controllers`` in test_outside_controllers.py. The world file only
says which nodes and parameters (and which interface packages to build, as colcon would).

    python controllers_of_their_own.py WORLD ROBOTS SEED ROBOT [multi-threaded]
"""
import json
import sys
from pathlib import Path

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor

from composed_sim import plugins
from composed_sim.hosting.building.nodes import controller_parameters
from composed_sim.interfaces import activate
from composed_sim.world.loader import load_world


def command(world_file, robots: int, seed: int, robot: int, threads: bool = False) -> list[str]:
    """The command line that starts robot ``robot``'s nodes in a process of their own."""
    return [sys.executable, str(Path(__file__)), str(world_file), str(robots), str(seed), str(robot),
            *(["multi-threaded"] if threads else [])]


def ros_args(namespace: str, parameters: dict, remappings: dict) -> list[str]:
    # On the simulator's clock, as a simulated robot's software is started (use_sim_time).
    args = ["--ros-args", "-r", f"__ns:=/{namespace}", "-p", "use_sim_time:=true"]
    for name, value in parameters.items():
        args += ["-p", f"{name}:={json.dumps(value)}"]       # a YAML value, as on the command line
    for source, target in remappings.items():
        args += ["-r", f"{source}:={target}"]
    return args


def main() -> None:
    path, robots, seed, robot = sys.argv[1], *map(int, sys.argv[2:5])
    threads = sys.argv[5:] == ["multi-threaded"]
    world = load_world(path, robots=robots, seed=seed)
    activate(world.interfaces)
    group_index = world.group_of_robot()[robot]
    group = world.robots[group_index]
    parameters = {p.name: p.value for p in controller_parameters(world, group_index)} if group.controller else {}
    for spec in group.node_specs:
        parameters.update(spec.parameters)
    remappings = {k: v for spec in group.node_specs for k, v in spec.remappings.items()}
    rclpy.init(args=ros_args(world.robot_names()[robot], parameters, remappings))
    executor = MultiThreadedExecutor() if threads else SingleThreadedExecutor()
    for spec in group.node_specs:
        executor.add_node(plugins.load(spec.node)())
    print(f"the nodes of {world.robot_names()[robot]} spinning", flush=True)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
