"""Building hosted controller nodes and the executor that runs them: shared by the composed host
and by each controller process of the multi-process host (which therefore imports no physics)."""
from __future__ import annotations

from rclpy.context import Context
from rclpy.executors import Executor, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from composed_sim import plugins
from composed_sim.ros.controller import PARAM_ROBOT_MODEL, PARAM_RUN_SEED
from composed_sim.ros.lockstep_executor import LockstepExecutor
from composed_sim.ros.simulator_node import quiet_node_options
from composed_sim.world.schema import World

EXECUTORS = ("lockstep", "events", "single-threaded", "multi-threaded")
MODES = ("composed", "multi-process")


class HostError(Exception):
    """The host cannot start: the message says what and why."""


def make_executor(kind: str, context: Context) -> Executor:
    if kind == "multi-threaded":
        return MultiThreadedExecutor(context=context)
    if kind == "single-threaded":
        return SingleThreadedExecutor(context=context)
    if kind == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    if kind == "lockstep":
        return LockstepExecutor(context=context)
    raise HostError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")


def controller_parameters(world: World, group_index: int) -> list[Parameter]:
    group = world.robots[group_index]
    params = [Parameter(k, value=v) for k, v in group.params.items()]
    return params + [Parameter(PARAM_ROBOT_MODEL, value=group.model), Parameter(PARAM_RUN_SEED, value=world.seed)]


def create_controller(cls: type[Node], name: str, world: World, group_index: int,
                      context: Context, use_sim_time: bool = False) -> Node:
    """Construct one plugin Node in the robot's namespace, and check the world's params exist."""
    group = world.robots[group_index]
    overrides = controller_parameters(world, group_index)
    if use_sim_time:
        overrides.append(Parameter("use_sim_time", value=True))
    try:
        node = cls(context=context, namespace=f"/{name}", use_global_arguments=False,
                   **quiet_node_options(overrides))
    except Exception as e:
        raise plugins.PluginError(f"controller plugin {group.controller!r} failed to construct for "
                                  f"{name}: {type(e).__name__}: {e}") from e
    unknown = [k for k in group.params if not node.has_parameter(k)]
    if unknown:
        declared = sorted(p for p in node._parameters if p not in ("use_sim_time", PARAM_ROBOT_MODEL, PARAM_RUN_SEED))
        node.destroy_node()
        raise plugins.PluginError(f"robots[{group_index}].params: controller {group.controller!r} has no "
                                  f"parameter {', '.join(map(repr, unknown))} (it declares: {', '.join(declared) or 'none'})")
    return node
