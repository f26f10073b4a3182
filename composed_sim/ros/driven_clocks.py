"""Sim time on the nodes' clocks: the one place that puts a clock on sim time and moves it.

A process's node with ``use_sim_time`` has its clock put on ROS time by rclpy's ``TimeSource``,
which then sets the time of each /clock message it hears. The host does the
same for the nodes it hosts, without a /clock subscription per node (N deliveries per tick): each
place that hosts nodes (a worker's participant groups, the run-wide nodes, a controller process,
the timers' clocks of hosting/sim_time/timers.py) calls ``follow_sim_time`` on a clock
once and ``set_sim_time`` as each tick opens. /clock is still published for everyone else."""
from __future__ import annotations

from typing import Iterable

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.time import Time

from composed_sim.ros import contract as c


def follow_sim_time(clock: Clock) -> None:
    """``clock`` reads sim time from now on, as ``use_sim_time`` puts a process's node: until its
    first time is set it reads 0 (in a constructor, before tick 0), never the wall clock."""
    clock._set_ros_time_is_active(True)


def set_sim_time(clocks: Iterable[Clock], stamp_ns: int, *, forward_only: bool = False) -> None:
    """Each of ``clocks`` reads ``stamp_ns`` from now on (``forward_only``: only those behind it,
    for clocks that more than one thing moves). As rclpy's ``Clock.set_ros_time_override``, whose
    type check is left out: the time is made here."""
    now = Time(nanoseconds=stamp_ns, clock_type=ClockType.ROS_TIME)._time_handle
    for clock in clocks:
        if forward_only and clock.now().nanoseconds >= stamp_ns:
            continue
        with clock.handle:
            clock.handle.set_ros_time_override(now)


class DrivenClocks:
    """The clocks of the nodes a simulator node drives, moved to each tick's time by it."""

    def __init__(self, tick_ns: int):
        self._tick_ns = tick_ns
        self._handles: list = []
        self.tick = -1              # the tick they read

    def drive(self, node: Node) -> None:
        clock = node.get_clock()
        follow_sim_time(clock)
        self._handles.append(clock.handle)

    def move_to(self, tick: int) -> None:
        """They read tick ``tick``'s time from now on (once per tick: as the tick opens, before
        anything of it reaches the nodes, as when a process hears /clock first)."""
        if tick == self.tick:
            return
        # Through the handles, without their guards: once per node and tick, for thousands of nodes
        # (docs/speed.md); the driven nodes live as long as their simulator node serves them, and
        # its thread drives them.
        now = Time.from_msg(c.stamp_of(tick, self._tick_ns))._time_handle
        for handle in self._handles:
            handle.set_ros_time_override(now)
        self.tick = tick
