"""Building a robot's hosted nodes, and the world's run-wide nodes, checked against the topic
contract: shared by the composed host, the worker processes, each controller process of the
multi-process host (which therefore import no physics)."""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Container, Mapping, Optional

from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from composed_sim import plugins
from composed_sim.hosting import HostError
from composed_sim.hosting.guard.node_logs import NodeLogs
from composed_sim.interfaces import InterfaceError, activate
from composed_sim.ros import contract as c
from composed_sim.world.robot_models import RANGE_AND_BEARING, get_model
from composed_sim.ros.controller import (PARAM_RAB_PAYLOAD_BYTES, PARAM_ROBOT_MODEL, PARAM_RUN_SEED,
                                         PARAM_SENSOR_TOPICS)
from composed_sim.hosting.building.lifecycle import AUTOSTART, LifecycleError, autostart
from composed_sim.hosting.building.node_options import HostedNodeOptions, construct
from composed_sim.hosting.building.wiring import answer_rule, answer_type, guard_publishers, robot_sensor_topics
from composed_sim.hosting.run_wide.relay import RunWideRelay
from composed_sim.hosting.sim_time.timers import SimTimers, first_timer_tick
from composed_sim.hosting.calls.clients import wait_during_construction
from composed_sim.hosting.calls.directory import remember_action_server_names
from composed_sim.hosting.guard.callback_guard import stop_robots_that_shut_down
from composed_sim.hosting.guard.node_logs import format_traceback
from composed_sim.hosting.sim_time.sleeps import host_clock_sleeps, host_rates, host_wall_sleeps
from composed_sim.hosting.sim_time.spins import host_global_spins
from composed_sim.world.crazyflies import interfaces_needed
from composed_sim.world.problems import format_path
from composed_sim.world.schema import NodeSpec, RobotGroup, World


def controller_parameters(world: World, group_index: int) -> list[Parameter]:
    group = world.robots[group_index]
    params = [Parameter(k, value=v) for k, v in group.params.items()]
    devices = group.devices.published(get_model(group.model))
    sensors = [t.name for t in c.robot_topics(devices) if t.direction == "sensor"]
    rab_bytes = world.range_and_bearing.payload_bytes if RANGE_AND_BEARING in devices else 0
    return params + [Parameter(PARAM_ROBOT_MODEL, value=group.model), Parameter(PARAM_RUN_SEED, value=world.seed),
                     Parameter(PARAM_SENSOR_TOPICS, Parameter.Type.STRING_ARRAY, sensors),
                     Parameter(PARAM_RAB_PAYLOAD_BYTES, value=rab_bytes)]


@dataclass
class BuiltNodes:
    """One robot's nodes (or the run-wide ones), built and checked, in the world file's order."""
    nodes: list[Node]
    # The timers of the nodes that do not follow the robot's sensors: the host moves them to each
    # tick's time (hosting/sim_time/timers.py).
    tick_timers: list[SimTimers]
    # No cmd_vel publisher yet, but one may come (wiring.answer_rule): the robot keeps its last
    # command until its first answer.
    answers_later: bool = False
    # The tick at which the first of its nodes' timers made before tick 0 first fires (0: none):
    # until then a robot that answers from a timer has had no chance to (sim_time/timers.py).
    first_timer_tick: int = 0


def node_field(group: RobotGroup, group_index: int, node_index: int) -> tuple:
    """The world file's field that names a robot's node: its ``controller``, or ``nodes[i]``."""
    return ("robots", group_index, "controller") if group.controller is not None \
        else ("robots", group_index, "nodes", node_index)


def _describe(field: tuple, spec: NodeSpec) -> str:
    """How messages name a node: ``robots[0].controller: controller plugin 'x'`` or
    ``robots[0].nodes[2]: node 'pkg.mod:Class'``."""
    path = format_path(field)
    return f"{path}: controller plugin {spec.node!r}" if field[-1] == "controller" else f"{path}: node {spec.node!r}"


def create_robot_nodes(world: World, group_index: int, name: str, context: Context, *,
                       classes: Mapping[str, type[Node]], relay: Optional[RunWideRelay] = None,
                       origin: int = 0, use_sim_time: bool = False, robots: Optional[Container[str]] = None,
                       clock_from_stamps: bool = False, logs: Optional[NodeLogs] = None,
                       warnings: Optional[SetupWarnings] = None) -> BuiltNodes:
    """Build robot ``name``'s nodes (its group's ``node_specs``) in its namespace, with their
    timers on sim time (hosting/sim_time/timers.py), their run-wide topics through ``relay`` (``origin``:
    the robot's index in the run), and check the world's parameters exist and the cmd_vel type.
    ``robots``: every robot's name (a set; computed from ``world`` when not given).
    ``clock_from_stamps``: the nodes' clocks follow a /clock that may arrive after the sensors (another
    process than the simulator's): a sensor stamp ahead of it moves it (``use_sim_time`` implies it).
    ``logs``: where the nodes' log lines go (``<robot>.log``, hosting/guard/node_logs.py); rclpy's loggers without.
    ``warnings``: the set-up warnings of the robots built so far (a new one without)."""
    warnings = SetupWarnings() if warnings is None else warnings
    group = world.robots[group_index]
    robots = frozenset(world.robot_names()) if robots is None else robots
    served = ServedByTick0(world, robots)
    sensors = robot_sensor_topics(group, name)
    overrides = controller_parameters(world, group_index)
    if use_sim_time:
        overrides.append(Parameter("use_sim_time", value=True))
    built = BuiltNodes([], [])
    timers_of: list[SimTimers] = []
    try:
        for ni, spec in enumerate(group.node_specs):
            field = node_field(group, group_index, ni)
            timers = SimTimers(world.tick_ns, follow_stamps=use_sim_time or clock_from_stamps)
            options = HostedNodeOptions(context, f"/{name}", [*overrides, *spec_parameters(spec)],
                                        spec.params_file, spec.remappings, hosted_logger(logs, name))
            node = construct_node(classes[spec.node], spec, field, name, options, timers, relay, origin, served)
            built.nodes.append(node)
            timers_of.append(timers)
        _bring_up(world, group_index, name, built, robots, relay)
        served.building = False
    except BaseException:
        for node in built.nodes:
            node.destroy_node()
        raise
    answers = answer_type(built.nodes, name, group.cmd_vel)
    # A robot that answers when published has no tick to miss: its timers' periods are its own.
    every = group.answers_every_ticks if group.answers == "every_tick" else None
    built.first_timer_tick = first_timer_tick(timers_of, world.tick_ns)
    for node, timers, spec in zip(built.nodes, timers_of, group.node_specs):
        guard_publishers(node, name, robots, answers, built.nodes)
        timers.started(sensors)
        if not timers.follows_sensors:
            built.tick_timers.append(timers)
        for warning in timers.period_warnings(spec.node, every):
            warnings.say(warning)
    return built


def _bring_up(world: World, group_index: int, name: str, built: BuiltNodes, robots: Container[str],
              relay: Optional[RunWideRelay]) -> None:
    """Robot ``name``'s nodes just built: its autostart lifecycle nodes configured and activated,
    their publishers checked against the contract, and whether they can answer its ticks."""
    group = world.robots[group_index]
    for ni, (node, spec) in enumerate(zip(built.nodes, group.node_specs)):
        if spec.lifecycle == AUTOSTART:
            field_of = node_field(group, group_index, ni)
            try:
                autostart(node, f"{_describe(field_of, spec)} of {name}")
            except LifecycleError as e:
                raise plugins.PluginError(str(e), field_of) from None
    # The publishers of the constructors and the autostart transitions are checked here
    # (nothing they published can answer a tick: no tick is open yet); the ones made later are
    # refused when created (guard_publishers).
    for ni, (node, spec) in enumerate(zip(built.nodes, group.node_specs)):
        problem = next((p for p in (c.publisher_problem(name, pub.topic_name, pub.msg_type, robots)
                                    for pub in node.publishers) if p), None)
        if problem is not None:
            raise plugins.PluginError(f"{_describe(node_field(group, group_index, ni), spec)} for {name}: "
                                      f"{problem}", node_field(group, group_index, ni))
    problem, built.answers_later = answer_rule(world, group_index, name, built.nodes, relay)
    if problem is not None:
        raise plugins.PluginError(f"{_describe(node_field(group, group_index, 0), group.node_specs[0])} "
                                  f"for {name}: {problem}", node_field(group, group_index, 0))


class ServedByTick0:
    """While nodes are built (constructors, autostart transitions): is a service of this name one
    the host will serve by tick 0, a robot's (in its namespace) or, in a world with run-wide nodes,
    one outside every robot's namespace? Once they are built, False: a wait is rclpy's own again.
    ``robots``: every robot's name."""

    def __init__(self, world: World, robots: Container[str]):
        # The run-wide nodes: the world's, and a world with drones has the crazyflie_server.
        self._robots = robots
        self._run_wide = bool(world.nodes) or any(get_model(g.model).flies for g in world.robots)
        self.building = True

    def __call__(self, name: str) -> bool:
        return self.building and (c.namespace_head(name) in self._robots or self._run_wide)


def hosted_logger(logs: Optional[NodeLogs], owner: Optional[str]):
    """``HostedNodeOptions.logger``: a node's lines to ``<owner>.log`` (None: the node's name)."""
    if logs is None:
        return None
    return lambda node: logs.logger(owner or node.get_name(), type(node), node.get_logger().name)


def spec_parameters(spec: NodeSpec) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in spec.parameters.items()]


def _own_frames(error: BaseException) -> str:
    """The frames of the traceback from the node's own code on (Python's own lines for them,
    indented), without the host's and rclpy's that led there nor the exception's line, which the
    error's own line says."""
    frames = format_traceback(error, skip="/composed_sim/,/rclpy/").splitlines()
    return "\n".join(line for line in frames if line.startswith("  "))


def _parameters_field(field: tuple) -> tuple:
    """The world file's field of a node's parameters: a controller's ``params``, a node's ``parameters``."""
    return field[:-1] + ("params",) if field[-1] == "controller" else field + ("parameters",)


def _what(field: tuple, spec: NodeSpec) -> str:
    return f"controller {spec.node!r}" if field[-1] == "controller" else f"node {spec.node!r}"


def _rejected_parameter(error: ParameterException, spec: NodeSpec) -> Optional[tuple[str, str]]:
    """(name, why) of the world file's parameter that rclpy refused (a declared type or range it
    does not fit), if the refusal is of one: rclpy's message is ``why: name``."""
    why, _, name = str(error).rpartition(": ")
    return (name, why) if name in spec.parameters else None


def construct_node(cls: type[Node], spec: NodeSpec, field: tuple, owner: str, options: HostedNodeOptions,
               timers: SimTimers, relay: Optional[RunWideRelay], origin: int, served: ServedByTick0) -> Node:
    """One node built by ``node_options.construct``; an error names the world file's field.
    ``served(name)``: will the host serve that service by tick 0?"""
    made = []                       # the node, once rclpy's constructor made it

    def prepare(node: Node) -> None:
        made.append(node)
        timers.prepare(node)
        host_rates(node)
        wait_during_construction(node, served)
        if relay is not None:
            relay.adopt(node, origin)
    try:
        node = construct(cls, options, prepare)
        host_clock_sleeps(node)
    except Exception as e:
        # The half-built node's endpoints go now, not when the exception's frames are collected:
        # until then other processes of the domain would see it.
        for half_built in made:
            if hasattr(half_built, "_Node__handle"):    # its Node.__init__ ran
                half_built.destroy_node()
        if isinstance(e, ParameterException) and (rejected := _rejected_parameter(e, spec)) is not None:
            # The world file's value, not the node's code: the field's line, no traceback. As in
            # ROS 2, a parameter keeps its declared type: 5 is no double.
            name, why = rejected
            where, value = _parameters_field(field) + (name,), spec.parameters[name]
            hint = f" (write {float(value)})" if type(value) is int and "'DOUBLE'" in why else ""
            raise plugins.PluginError(f"{format_path(where)}: {_what(field, spec)} refuses {value!r}: {why}{hint}",
                                      where) from None
        raise plugins.PluginError(f"{_describe(field, spec)} failed to construct for {owner}: "
                                  f"{type(e).__name__}: {e}", field, _own_frames(e)) from e
    if node.executor is not None:
        # Its constructor gave it an executor of its own (spun in a thread, say): hosted, the host
        # spins it, and adding it to the host's executor would take it from that one, which would
        # silently spin nothing.
        kind = type(node.executor).__name__
        node.destroy_node()
        raise plugins.PluginError(f"{_describe(field, spec)} for {owner}: its constructor adds it to an executor of "
                                  f"its own ({kind}): a hosted node is spun by the host's executor, which gives it "
                                  f"the callback groups, services and actions of its own process; leave spinning "
                                  f"to the code that starts it (its main())", field)
    unknown = [k for k in spec.parameters if not node.has_parameter(k)]
    if unknown:
        plumbing = ("use_sim_time", PARAM_ROBOT_MODEL, PARAM_RUN_SEED, PARAM_SENSOR_TOPICS,
                    PARAM_RAB_PAYLOAD_BYTES, START_TYPE_DESCRIPTION_SERVICE_PARAM)
        declared = sorted(p for p in node._parameters if p not in plumbing)
        node.destroy_node()
        where = _parameters_field(field)
        raise plugins.PluginError(f"{format_path(where)}: {_what(field, spec)} has no parameter {', '.join(map(repr, unknown))} "
                                  f"(it declares: {', '.join(declared) or 'none'})", where)
    return node


def before_node_imports() -> None:
    """What must be in place before any node's module is imported, by whoever imports it (one may
    bind ``from time import sleep``): the calls that would act on their whole process act on their
    robot (hosting/sim_time/sleeps.py, hosting/guard/callback_guard.py). Idempotent."""
    host_wall_sleeps()
    host_global_spins()
    stop_robots_that_shut_down()
    remember_action_server_names()


def load_classes(world: World) -> dict[str, type[Node]]:
    """Every node class the world names (robots' and run-wide), imported once, after the world's
    interface packages are built (or found built) and importable (composed_sim/interfaces/)."""
    before_node_imports()
    try:
        activate(world.interfaces, interfaces_needed(world))
    except InterfaceError as e:
        raise HostError(str(e)) from None
    names = [spec.node for g in world.robots for spec in g.node_specs] + [spec.node for spec in world.nodes]
    return {name: plugins.load(name) for name in dict.fromkeys(names)}


class SetupWarnings:
    """The set-up warnings of a process's robots, each said once (it would otherwise repeat for
    every robot of a group)."""

    def __init__(self) -> None:
        self._said: set[str] = set()

    def say(self, message: str) -> None:
        if message not in self._said:
            self._said.add(message)
            print(f"composed-sim: warning: {message}", file=sys.stderr)
