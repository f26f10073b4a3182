"""``rclpy.spin_once(node)``, ``rclpy.spin_until_future_complete(node, future)`` and
``rclpy.spin(node)`` called inside a hosted callback, on rclpy's global executor.

In its own process a node that spins inside one of its callbacks (a vendor's action server turns
the robot with ``rclpy.spin_once(self, timeout_sec=0.1)`` in a loop, reading its odometry between
commands) runs its other callbacks from there, one per ``spin_once``, or waits up to the timeout.
Hosted, the node is in the host's executor and rclpy's global executor has no context (the host
never initialises the default one): rclpy would fail inside the callback, and an action server
swallows that and aborts the goal in silence. So, while a lockstep walk runs the caller, rclpy's
global executor is the caller's own, seen through ``CallerExecutor``:

- ``spin_once(timeout_sec)`` sets the caller aside until another callback of the node has run
  (the walk runs it: a message, a timer, a service), or the timeout has passed on the node's clock
  (sim time; ``None`` or negative: no timeout; 0: until the clock moves, the next tick);
- ``spin_until_future_complete(future, timeout_sec)`` sets it aside until ``future`` is done, or
  the timeout has passed on the node's clock;
- ``spin()`` is ``spin_once()`` until the node's context is shut down.

Everywhere else (the host's own code, a node's constructor, a stock executor's callbacks) rclpy's
global executor is rclpy's own.
"""
from __future__ import annotations

from typing import Optional

import rclpy
from greenlet import getcurrent
from rclpy.task import Future

from composed_sim.hosting.sim_time.sleeps import can_set_aside, wait_on_clock

_TICK = 1e-9        # a timeout of 0 waits for the clock to move at all: the next tick


class CallerExecutor:
    """What rclpy's spin functions get as the global executor inside a hosted callback: the part of
    ``Executor`` they use, each a wait of the caller on the executor that runs it."""

    def __init__(self, executor):
        self._executor = executor
        self._node = None

    @property
    def context(self):
        return (self._node or next(iter(self._executor.get_nodes()))).context

    def add_node(self, node) -> bool:
        self._node = node
        return False                # the host's executor has it: rclpy must not remove it after

    def remove_node(self, node) -> None:
        pass

    def create_task(self, callback, *args, **kwargs):
        return self._executor.create_task(callback, *args, **kwargs)

    def spin_once(self, timeout_sec: Optional[float] = None) -> None:
        executor, node = self._executor, self._node
        ran = Future()
        executor.notify_after_callback_of(node, ran)
        wait_on_clock(node, executor, ran, executor.group_of_caller(), _timeout(timeout_sec),
                      lambda: ran.set_result(None))

    def spin_until_future_complete(self, future: Future, timeout_sec: Optional[float] = None) -> None:
        executor, node = self._executor, self._node
        if future.done():
            return
        ended = Future()
        future.add_done_callback(lambda _: ended.done() or ended.set_result(None))
        wait_on_clock(node, executor, ended, executor.group_of_caller(), _timeout(timeout_sec),
                      lambda: ended.done() or ended.set_result(None))

    def spin(self) -> None:
        while self.context.ok():
            self.spin_once()


def _timeout(timeout_sec: Optional[float]) -> Optional[float]:
    if timeout_sec is None or timeout_sec < 0:
        return None
    return max(timeout_sec, _TICK)


def host_global_spins() -> None:
    """rclpy's global executor is the calling callback's own executor while a lockstep walk runs
    it (``CallerExecutor``), rclpy's own everywhere else. Idempotent."""
    if getattr(rclpy.get_global_executor, "hosted", False):
        return
    rclpy_global = rclpy.get_global_executor

    def get_global_executor():
        scheduler = getattr(getcurrent(), "scheduler", None)      # the walk's (hosting/executors/scheduler.py)
        executor = scheduler.owner if scheduler is not None else None
        if executor is not None and can_set_aside(executor):
            return CallerExecutor(executor)
        return rclpy_global()
    get_global_executor.hosted = True
    rclpy.get_global_executor = get_global_executor
