"""The world's run-wide nodes (``nodes:`` at the top of a world file), hosted once per run.

They live in one participant of the process that publishes /clock, outside every robot's
namespace, and the host drives them itself at the start of each tick, with a lockstep executor
of their own whatever the robots' executor: their timers due by the tick's time fire, and what
they have to handle runs, before the tick's run-wide batch goes out (hosting/run_wide/relay.py). So a start
command that a run-wide node publishes at tick 0 reaches every robot before its tick-0 sensors.
"""
from __future__ import annotations

from typing import Callable, Collection, Optional

from rclpy.context import Context
from rclpy.node import Node
from rclpy.time import Time

from composed_sim.hosting.entities import HostedEntities
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.executors.running import run_until_idle
from composed_sim.hosting.outside_calls import OutsideCalls
from composed_sim.hosting.run_wide.calls import CallRelay
from composed_sim.hosting.run_wide.relay import RUN_WIDE_ORIGIN, RunWideRelay
from composed_sim.hosting.services import ServiceDirectory
from composed_sim.hosting.sim_timers import SimTimers



class RunWideNodes:
    """The run-wide nodes built (``building.create_run_wide_nodes``), their timers, their executor."""

    def __init__(self, nodes: list[Node], tick_timers: list[SimTimers], tick_ns: int, context: Context):
        self._tick_ns = tick_ns
        self._nodes, self._tick_timers = nodes, tick_timers
        self._executor = LockstepExecutor(context=context)
        self._outside_calls: Optional[OutsideCalls] = None
        for node in nodes:
            node.get_clock()._set_ros_time_is_active(True)
            self._executor.add_node(node)

    def host(self, relay: RunWideRelay, calls: CallRelay, robots: Collection[str],
             graph_changed: Optional[Callable[[], bool]] = None) -> None:
        """Their services, clients and parameter services, hosted as the robots' are: calls to
        and from robots through ``calls`` (hosting/run_wide/calls.py), from other processes at
        the start of their part of each tick (``robots``: the run's). ``graph_changed``: has their
        participant's ROS graph changed, from the host's own watch where it has one (a second
        watch of the same participant would take its triggers); else they watch it themselves."""
        directory = ServiceDirectory(self._executor, relay=calls)
        calls.serve([RUN_WIDE_ORIGIN], directory)
        entities = HostedEntities(directory, relay)
        for node in self._nodes:
            entities.adopt(node, None, RUN_WIDE_ORIGIN)
        if graph_changed is not None:
            self._outside_calls = OutsideCalls(directory, robots, graph_changed)
        elif self._nodes:
            self._outside_calls = OutsideCalls.watching(directory, robots, self._nodes[0])

    def run_until_idle(self) -> None:
        """Run what is ready (calls handed over to them) until nothing is."""
        run_until_idle(self._executor)

    @property
    def nodes(self) -> list[Node]:
        return self._nodes

    def start_tick(self, tick: int) -> None:
        """Their part of tick ``tick``: the clock moves to the tick's time, their timers due by then
        fire, and whatever is ready runs until nothing is."""
        now_ns = tick * self._tick_ns
        now = Time(nanoseconds=now_ns)
        for node in self._nodes:
            node.get_clock().set_ros_time_override(now)
        for timers in self._tick_timers:
            timers.advance_to(now_ns)
        if self._outside_calls is not None:
            self._outside_calls.take()
        run_until_idle(self._executor)

    def destroy(self) -> None:
        if self._outside_calls is not None:
            self._outside_calls.close()
        self._executor.shutdown()
        for node in self._nodes:
            node.destroy_node()
