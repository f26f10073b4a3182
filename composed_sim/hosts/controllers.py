"""Building hosted controller nodes and the executor that runs them: shared by the composed host
and by each controller process of the multi-process host (which therefore imports no physics)."""
from __future__ import annotations

import inspect
import sys
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
from composed_sim.ros.sim_timers import SimTimers
from composed_sim.ros.robot_settings import quiet_node_options
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


def guard_publishers(node: Node, robot: str, robots: Container[str], answer_type: Optional[type]) -> None:
    """Make ``node.create_publisher`` refuse another robot's topic, a sensor topic or a wrong
    type on its own actuator topic (``contract.publisher_problem``; on cmd_vel: another type than its
    answers have, ``answer_type`` or the one of its first cmd_vel publisher): the fault is the
    publishing robot's, found where it starts, and no other robot ever receives a foreign answer."""
    create = node.create_publisher

    def create_publisher(msg_type, topic, *args, **kwargs):
        problem = c.publisher_problem(robot, node.resolve_topic_name(topic), msg_type, robots,
                                      answer_type or published_answer_type(node, robot))
        if problem is not None:
            raise ContractViolation(problem)
        return create(msg_type, topic, *args, **kwargs)
    node.create_publisher = create_publisher


def create_controller(cls: type[Node], name: str, world: World, group_index: int,
                      context: Context, use_sim_time: bool = False,
                      robots: Optional[Container[str]] = None, clock_from_stamps: bool = False) -> Node:
    """Construct one plugin Node in the robot's namespace, with its timers on sim time
    (ros/sim_timers.py), and check the world's params exist and its cmd_vel type.
    ``robots``: every robot's name (a set; computed from ``world`` when not given).
    ``clock_from_stamps``: the node's clock follows a /clock that may arrive after the sensors (another
    process than the simulator's): a sensor stamp ahead of it moves it (``use_sim_time`` implies it)."""
    group = world.robots[group_index]
    where = ("robots", group_index, "controller")
    problem = node_options_problem(cls)
    if problem is not None:
        raise plugins.PluginError(f"robots[{group_index}].controller: controller plugin {group.controller!r}: "
                                  f"{problem}", where)
    overrides = controller_parameters(world, group_index)
    if use_sim_time:
        overrides.append(Parameter("use_sim_time", value=True))
    robots = frozenset(world.robot_names()) if robots is None else robots
    timers = SimTimers(world.tick_ns, follow_stamps=use_sim_time or clock_from_stamps)
    try:
        node = timers.construct(cls, context=context, namespace=f"/{name}", use_global_arguments=False,
                                **quiet_node_options(overrides))
    except Exception as e:
        raise plugins.PluginError(f"robots[{group_index}].controller: controller plugin {group.controller!r} "
                                  f"failed to construct for {name}: {type(e).__name__}: {e}", where) from e
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
    problems = [c.publisher_problem(name, p.topic_name, p.msg_type, robots) for p in node.publishers]
    problems += [answer_type_problem(node, name, group.cmd_vel)]
    if any(problems):
        node.destroy_node()
        raise plugins.PluginError(f"robots[{group_index}].controller: controller plugin {group.controller!r} "
                                  f"for {name}: {next(p for p in problems if p)}", where)
    guard_publishers(node, name, robots, answer_type(node, name, group.cmd_vel))
    sensors = [c.topic_name(name, t) for t in c.robot_topics(group.devices.published(get_model(group.model)))
               if t.direction == "sensor"]
    timers.started(sensors)
    for warning in timers.period_warnings(group.controller, group.answers_every_ticks):
        warn_once(warning)
    return node


def node_options_problem(cls: type[Node]) -> Optional[str]:
    """A controller class must take the host's node options (context, namespace, parameters…) and
    pass them on to ``Node.__init__``, as an rclcpp component takes ``NodeOptions``."""
    try:
        parameters = inspect.signature(cls.__init__).parameters.values()
    except (TypeError, ValueError):
        return None
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return None
    return (f"{cls.__module__}.{cls.__qualname__}.__init__ takes no **kwargs: accept them and pass them on, "
            f"``def __init__(self, **kwargs): super().__init__('name', **kwargs)``, so that the host can give the "
            f"node its context, namespace and parameters")


def published_answer_type(node: Node, robot: str) -> Optional[type]:
    """The type of ``node``'s publisher on its robot's cmd_vel, None without one."""
    topic = c.topic_name(robot, c.CMD_VEL)
    return next((p.msg_type for p in node.publishers if p.topic_name == topic), None)


def answer_type(node: Node, robot: str, declared: str) -> Optional[type]:
    """What ``robot``'s answers will be: the world file's ``cmd_vel`` type (stamped, unstamped),
    else (auto) its publisher's, else None: not known yet (a publisher created later)."""
    return c.ANSWER_TYPES[declared] if declared != "auto" else published_answer_type(node, robot)


def answer_type_problem(node: Node, robot: str, declared: str) -> Optional[str]:
    """The world file's ``cmd_vel`` (stamped, unstamped) against what the node publishes."""
    found = published_answer_type(node, robot)
    if declared == "auto" or found is None or found is c.ANSWER_TYPES[declared]:
        return None
    return (f"it publishes {c.type_name(found)} on {c.topic_name(robot, c.CMD_VEL)}, but the world file says "
            f"cmd_vel: {declared} ({c.type_name(c.ANSWER_TYPES[declared])})")


_warned: set[str] = set()


def warn_once(message: str) -> None:
    """A set-up warning, once per process (it would otherwise repeat for every robot of a group)."""
    if message not in _warned:
        _warned.add(message)
        print(f"composed-sim: warning: {message}", file=sys.stderr)
