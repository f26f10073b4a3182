"""The clocks of the nodes a simulator node drives: set to each tick's sim time by the host itself,
so that a hosted node sees sim time without a /clock subscription of its own (N deliveries per
tick); /clock is still published for everyone else."""
from __future__ import annotations

from rclpy.node import Node
from rclpy.time import Time

from composed_sim.ros import contract as c


class DrivenClocks:
    def __init__(self, tick_ns: int):
        self._tick_ns = tick_ns
        self._handles: list = []
        self.tick = -1              # the tick they read

    def drive(self, node: Node) -> None:
        clock = node.get_clock()
        clock._set_ros_time_is_active(True)
        self._handles.append(clock.handle)

    def move_to(self, tick: int) -> None:
        """They read tick ``tick``'s time from now on (once per tick: as the tick opens, before
        anything of it reaches the nodes, as when a process hears /clock first)."""
        if tick == self.tick:
            return
        # Through the handles: rclpy's ``set_ros_time_override`` checks the type and takes the
        # guard on each call, several times the cost (docs/speed.md); the driven nodes live as long
        # as their simulator node serves them, and its thread drives them.
        now = Time.from_msg(c.stamp_of(tick, self._tick_ns))._time_handle
        for handle in self._handles:
            handle.set_ros_time_override(now)
        self.tick = tick
