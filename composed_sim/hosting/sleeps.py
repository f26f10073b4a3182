"""A hosted node's waits on its clock: a rate's ``sleep()`` and the clock's ``sleep_for`` and
``sleep_until``, on sim time.

In its own process, a callback that sleeps on a rate or on the node's clock blocks one of the
executor's threads while the others run, and wakes when the clock (sim time, from /clock) gets
there. Hosted, the callback is set aside by the lockstep executor (hosting/executors/scheduler.py)
and resumed from the walk once the node's timer for that time fires, at the tick the clock gets
there (hosting/sim_timers.py): the same tick in every run. With a stock executor, or outside a
callback, rclpy's own wait.
"""
from __future__ import annotations

from typing import Optional

from rclpy.clock import Clock
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.task import Future
from rclpy.time import Time


def _executor_that_can_wait(node: Node):
    executor = node.executor
    return executor if getattr(executor, "can_wait", lambda: False)() else None


def host_rates(node: Node) -> None:
    """Before ``node``'s constructor: the rates it creates sleep as hosted waits."""
    create_rate = node.create_rate

    def hosted_create_rate(frequency: float, clock: Optional[Clock] = None):
        rate = create_rate(frequency, clock)
        sleepers: list[Future] = []
        fired = rate._event.set
        plain_sleep = rate.sleep

        def on_timer():
            fired()
            while sleepers:
                sleepers.pop(0).set_result(None)

        def sleep():
            executor = _executor_that_can_wait(node)
            if executor is None:
                return plain_sleep()
            if not rate._event.is_set():          # its timer has not fired since the last sleep
                future = Future()
                sleepers.append(future)
                executor.wait_for(future, executor.group_of_caller())
            rate._event.clear()
        rate._timer.callback = on_timer
        rate.sleep = sleep
        return rate
    node.create_rate = hosted_create_rate


def host_clock_sleeps(node: Node) -> None:
    """The node's clock's ``sleep_until`` and ``sleep_for`` as hosted waits (after its
    constructor: the clock is made by ``Node.__init__``)."""
    clock = node.get_clock()
    plain_until = clock.sleep_until

    def sleep_until(until: Time, context=None) -> bool:
        executor = _executor_that_can_wait(node)
        if executor is None:
            return plain_until(until, context)
        left_ns = until.nanoseconds - clock.now().nanoseconds
        if left_ns > 0:
            future = Future()
            timer = node.create_timer(left_ns * 1e-9, lambda: future.done() or future.set_result(None))
            try:
                executor.wait_for(future, executor.group_of_caller())
            finally:
                node.destroy_timer(timer)
        return True

    def sleep_for(rel_time: Duration, context=None) -> bool:
        return sleep_until(clock.now() + rel_time, context)
    clock.sleep_until, clock.sleep_for = sleep_until, sleep_for
