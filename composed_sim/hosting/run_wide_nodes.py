"""The world's run-wide nodes (``nodes:`` at the top of a world file), hosted once per run.

They live in one participant of the process that publishes /clock, outside every robot's
namespace, and the host drives them itself at the start of each tick, with a lockstep executor
of their own whatever the robots' executor: their timers due by the tick's time fire, and what
they have to handle runs, before the tick's run-wide batch goes out (hosting/run_wide/relay.py). So a start
command that a run-wide node publishes at tick 0 reaches every robot before its tick-0 sensors. One
it publishes from a timer goes out at the timer's first period (as in rclpy, not at tick 0): until
then (``first_timer_tick``) the robots, which may be waiting for it, keep their last command
without a violation, as they do before their own nodes' first timer (ros/answer_ledger.py).
"""
from __future__ import annotations

from typing import Callable, Collection, Iterable, Mapping, Optional

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from composed_sim.hosting.hosted_block import HostedBlock
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.executors.running import run_until_idle
from composed_sim.hosting.building.node_options import HostedNodeOptions
from composed_sim.hosting.building.nodes import BuiltNodes, ServedByTick0, construct_node, hosted_logger, spec_parameters
from composed_sim.hosting.guard.node_logs import NodeLogs
from composed_sim.hosting.calls.between_places import RUN_WIDE_ORIGIN, CallRelay
from composed_sim.hosting.drones import run_wide_specs, with_server_class
from composed_sim.hosting.run_wide.relay import RunWideRelay
from composed_sim.ros.controller import PARAM_RUN_SEED
from composed_sim.ros.driven_clocks import follow_sim_time, set_sim_time
from composed_sim.world.schema import World
from composed_sim.hosting.sim_time.timers import SimTimers, first_timer_tick



class RunWideNodes:
    """The run-wide nodes built (``building.create_run_wide_nodes``), their timers, their executor."""

    def __init__(self, nodes: list[Node], tick_timers: list[SimTimers], tick_ns: int, context: Context):
        self._tick_ns = tick_ns
        self._nodes, self._tick_timers = nodes, tick_timers
        self._executor = LockstepExecutor(context=context)
        self._block: Optional[HostedBlock] = None
        for node in nodes:
            follow_sim_time(node.get_clock())
            self._executor.add_node(node)

    def host(self, relay: RunWideRelay, calls: CallRelay, robots: Collection[str],
             graph_changed: Optional[Callable[[], bool]] = None) -> None:
        """Their services, clients and parameter services, hosted as the robots' are: calls to
        and from robots through ``calls`` (hosting/calls/between_places.py), from other processes at
        the start of their part of each tick (``robots``: the run's). ``graph_changed``: has their
        participant's ROS graph changed, from the host's own watch where it has one (a second
        watch of the same participant would take its triggers); else they watch it themselves."""
        self._block = HostedBlock(self._executor, [(node, None, RUN_WIDE_ORIGIN, None) for node in self._nodes],
                                  robots=robots, graph_changed=graph_changed, calls=calls,
                                  places=[RUN_WIDE_ORIGIN], relay=relay)

    def run_until_idle(self) -> None:
        """Run what is ready (calls handed over to them) until nothing is."""
        run_until_idle(self._executor)

    @property
    def nodes(self) -> list[Node]:
        return self._nodes

    @property
    def first_timer_tick(self) -> int:
        """The tick at which the first of their timers made before tick 0 first fires (0: none)."""
        return first_timer_tick(self._tick_timers, self._tick_ns)

    def start_tick(self, tick: int) -> None:
        """Their part of tick ``tick``: the clock moves to the tick's time, their timers due by then
        fire, and whatever is ready runs until nothing is."""
        now_ns = tick * self._tick_ns
        set_sim_time([node.get_clock() for node in self._nodes], now_ns)
        for timers in self._tick_timers:
            timers.advance_to(now_ns)
        if self._block is not None:
            self._block.start_tick()
        run_until_idle(self._executor)

    def destroy(self) -> None:
        if self._block is not None:
            self._block.close()
        self._executor.shutdown()
        for node in self._nodes:
            node.destroy_node()


def first_timer_tick_of(run_wide: Optional[RunWideNodes]) -> int:
    """``RunWideNodes.first_timer_tick``, 0 where there are none (or none in this process)."""
    return run_wide.first_timer_tick if run_wide is not None else 0


def wait_for_run_wide_timers(simulator_nodes: Iterable, tick: int) -> None:
    """The run-wide nodes' first timer fires at tick ``tick`` (0: none): until then a robot may be
    waiting for what they publish from it (a start command) and has had no chance to answer, as
    before its own nodes' first timer. Each robot of ``simulator_nodes`` keeps its last command
    without a violation until its first answer or that tick (ros/answer_ledger.py)."""
    if tick > 0:
        for node in simulator_nodes:
            node.answer_later(node.robots, until_tick=tick)


def create_run_wide_nodes(world: World, context: Context, *, classes: Mapping[str, type[Node]],
                          relay: RunWideRelay, logs: Optional[NodeLogs] = None) -> RunWideNodes:
    """Build the world's run-wide nodes (``world.nodes``) outside every robot's namespace, their
    timers on sim time, moved to each tick's time by the host; their run-wide topics through ``relay``;
    their log lines to ``logs`` (``<node>.log``). A world with drones has the crazyflie_server too
    (hosting/drones.py)."""
    built = BuiltNodes([], [])
    served = ServedByTick0(world, frozenset(world.robot_names()))
    classes = with_server_class(world, classes)
    try:
        for ni, spec in enumerate(run_wide_specs(world)):
            timers = SimTimers(world.tick_ns)
            options = HostedNodeOptions(context, "/", [Parameter(PARAM_RUN_SEED, value=world.seed),
                                                       *spec_parameters(spec)], spec.params_file, spec.remappings,
                                        hosted_logger(logs, None))
            built.nodes.append(construct_node(classes[spec.node], spec, ("nodes", ni), "the run", options, timers,
                                          relay, RUN_WIDE_ORIGIN, served))
            timers.started(())
            built.tick_timers.append(timers)
        served.building = False
    except BaseException:
        for node in built.nodes:
            node.destroy_node()
        raise
    return RunWideNodes(built.nodes, built.tick_timers, world.tick_ns, context)
