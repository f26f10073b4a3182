"""Building hosted controller nodes and the executor that runs them: shared by the composed host
and by each controller process of the multi-process host (which therefore imports no physics)."""
from __future__ import annotations

from typing import Container, Optional

from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from composed_sim import plugins
from composed_sim.hosts.choices import EXECUTORS
from composed_sim.ros import contract as c
from composed_sim.world.robot_models import RANGE_AND_BEARING, get_model
from composed_sim.ros.controller import (PARAM_RAB_PAYLOAD_BYTES, PARAM_ROBOT_MODEL, PARAM_RUN_SEED,
                                         PARAM_SENSOR_TOPICS)
from composed_sim.ros.lockstep_executor import LockstepExecutor
from composed_sim.ros.simulator_node import quiet_node_options
from composed_sim.world.schema import World



class HostError(Exception):
    """The host cannot start: the message says what and why."""


def check_executor(kind: str) -> None:
    if kind not in EXECUTORS:
        raise HostError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")


def spin_until_shutdown(executor: Executor) -> None:
    """An executor's spin() for a background thread: ends quietly when the executor is shut down."""
    try:
        executor.spin()
    except ExternalShutdownException:
        pass


def matched(endpoint) -> bool:
    """A publisher with a matched subscription, a subscription with a matched publisher; True for
    None (a topic the caller does not serve, e.g. /clock, shared by all)."""
    if endpoint is None:
        return True
    count = endpoint.get_subscription_count() if hasattr(endpoint, "get_subscription_count") \
        else endpoint.get_publisher_count()
    return count >= 1


def make_executor(kind: str, context: Context) -> Executor:
    if kind == "multi-threaded":
        return MultiThreadedExecutor(context=context)
    if kind == "single-threaded":
        return SingleThreadedExecutor(context=context)
    if kind == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    check_executor(kind)
    return LockstepExecutor(context=context)


def controller_parameters(world: World, group_index: int) -> list[Parameter]:
    group = world.robots[group_index]
    params = [Parameter(k, value=v) for k, v in group.params.items()]
    devices = group.devices.published(get_model(group.model))
    sensors = [t.name for t in c.robot_topics(devices) if t.direction == "sensor"]
    rab_bytes = world.range_and_bearing.payload_bytes if RANGE_AND_BEARING in devices else 0
    return params + [Parameter(PARAM_ROBOT_MODEL, value=group.model), Parameter(PARAM_RUN_SEED, value=world.seed),
                     Parameter(PARAM_SENSOR_TOPICS, Parameter.Type.STRING_ARRAY, sensors),
                     Parameter(PARAM_RAB_PAYLOAD_BYTES, value=rab_bytes)]


class ContractViolation(Exception):
    """A controller tried to publish what the topic contract does not allow it to."""


def guard_publishers(node: Node, robot: str, robots: Container[str]) -> None:
    """Make ``node.create_publisher`` refuse another robot's topic, a sensor topic or a wrong
    type on its own actuator topic (``contract.publisher_problem``): the fault is the
    publishing robot's, found where it starts, and no other robot ever receives a foreign answer."""
    create = node.create_publisher

    def create_publisher(msg_type, topic, *args, **kwargs):
        problem = c.publisher_problem(robot, node.resolve_topic_name(topic), msg_type, robots)
        if problem is not None:
            raise ContractViolation(problem)
        return create(msg_type, topic, *args, **kwargs)
    node.create_publisher = create_publisher


def create_controller(cls: type[Node], name: str, world: World, group_index: int,
                      context: Context, use_sim_time: bool = False,
                      robots: Optional[Container[str]] = None) -> Node:
    """Construct one plugin Node in the robot's namespace, and check the world's params exist.
    ``robots``: every robot's name (a set; computed from ``world`` when not given)."""
    group = world.robots[group_index]
    overrides = controller_parameters(world, group_index)
    if use_sim_time:
        overrides.append(Parameter("use_sim_time", value=True))
    robots = frozenset(world.robot_names()) if robots is None else robots
    try:
        node = cls(context=context, namespace=f"/{name}", use_global_arguments=False,
                   **quiet_node_options(overrides))
    except Exception as e:
        raise plugins.PluginError(f"robots[{group_index}].controller: controller plugin {group.controller!r} "
                                  f"failed to construct for {name}: {type(e).__name__}: {e}",
                                  ("robots", group_index, "controller")) from e
    unknown = [k for k in group.params if not node.has_parameter(k)]
    if unknown:
        plumbing = ("use_sim_time", PARAM_ROBOT_MODEL, PARAM_RUN_SEED, PARAM_SENSOR_TOPICS,
                    PARAM_RAB_PAYLOAD_BYTES, START_TYPE_DESCRIPTION_SERVICE_PARAM)
        declared = sorted(p for p in node._parameters if p not in plumbing)
        node.destroy_node()
        raise plugins.PluginError(f"robots[{group_index}].params: controller {group.controller!r} has no "
                                  f"parameter {', '.join(map(repr, unknown))} (it declares: {', '.join(declared) or 'none'})",
                                  ("robots", group_index, "params"))
    # The constructor's publishers are checked here (nothing it published can answer a tick:
    # no tick is open yet); the ones it creates later are refused when created.
    for publisher in node.publishers:
        problem = c.publisher_problem(name, publisher.topic_name, publisher.msg_type, robots)
        if problem is not None:
            node.destroy_node()
            raise plugins.PluginError(f"robots[{group_index}].controller: controller plugin {group.controller!r} "
                                      f"for {name}: {problem}", ("robots", group_index, "controller"))
    guard_publishers(node, name, robots)
    return node
