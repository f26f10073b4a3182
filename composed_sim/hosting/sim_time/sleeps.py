"""A hosted node's waits on its clock: a rate's ``sleep()`` and the clock's ``sleep_for`` and
``sleep_until``, on sim time.

In its own process, a callback that sleeps on a rate or on the node's clock blocks one of the
executor's threads while the others run, and wakes when the clock (sim time, from /clock) gets
there. Hosted, the callback is set aside by the lockstep executor (hosting/executors/scheduler.py)
and resumed from the walk once the node's timer for that time fires, at the tick the clock gets
there (hosting/sim_time/timers.py): the same tick in every run. With a stock executor, or outside a
callback, rclpy's own wait.

``time.sleep`` in a hosted callback is the same wait, on the run's clock: in its own process the
callback would hold one thread of the executor for that long while the others go on (serving the
node's other callbacks: an action server's cancel, the next goal) and, on sim time at real-time
pace, see the world move on by as much. Hosted by the hundred in one thread, it would hold up the
whole host instead. So the callback is set aside for that long on the node's clock, said once.
rclpy's own polling sleeps (``wait_for_service``, ``wait_for_server``) stay on the wall clock, as
in any process: they poll the ROS graph, on which what the run serves is there at once.
"""
from __future__ import annotations

import sys
import time
from typing import Callable, Optional

from greenlet import getcurrent
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.task import Future
from rclpy.time import Time


SLEEP_HOOK = "on_sleep"      # a callback's greenlet may name what to tell when it sleeps (timers.py)


def _tell_sleeping() -> None:
    """The calling callback is about to be set aside until a later time on its clock: tell whoever
    asked (a sensor callback's node's timers, which then need not wait for it to return)."""
    hook = getattr(getcurrent(), SLEEP_HOOK, None)
    if hook is not None:
        hook()


def can_set_aside(executor) -> bool:
    """Is the caller a callback that ``executor`` can set aside while it waits (the lockstep
    executor's walk runs it)?"""
    return getattr(executor, "can_wait", lambda: False)()


def wait_on_clock(node: Node, executor, future: Future, group, seconds: Optional[float],
                  at_time: Callable[[], object]) -> None:
    """Set the calling callback (of ``group``) aside in ``executor`` until ``future`` is done;
    ``seconds`` later on the node's clock (sim time: the same tick in every run), ``at_time()``
    first, if not done."""
    # A group of its own, as rclpy gives its rates: the caller's group may be held while it waits.
    # On the node's clock itself, which the host moves as each tick opens, not on the timers'
    # clocks (sim_time/timers.py), which move once the tick's sensor callbacks have returned: a
    # sensor callback that sleeps has not returned, and the next one, of its mutually exclusive
    # group, cannot start, so that clock would never get there.
    timer = None if seconds is None else node.create_timer(seconds, lambda: future.done() or at_time(),
                                                           callback_group=ReentrantCallbackGroup(),
                                                           clock=node.get_clock())
    try:
        executor.wait_for(future, group)
    finally:
        if timer is not None:
            node.destroy_timer(timer)


def _executor_that_can_wait(node: Node):
    executor = node.executor
    return executor if can_set_aside(executor) else None


def host_rates(node: Node) -> None:
    """Before ``node``'s constructor: the rates it creates sleep as hosted waits."""
    create_rate = node.create_rate

    def hosted_create_rate(frequency: float, clock: Optional[Clock] = None):
        # On the node's clock, which the host moves as each tick opens (as ``wait_on_clock``'s
        # timer), not on a timers' clock of sim_time/timers.py, which waits for the tick's sensor
        # callbacks: one of them may be the sleeper, or wait for the sleeper's group.
        rate = create_rate(frequency, clock or node.get_clock())
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
                _tell_sleeping()
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
        if executor is None:        # rclpy's wait, in the node's context (its process's default)
            return plain_until(until, context or node.context)
        left_ns = until.nanoseconds - clock.now().nanoseconds
        if left_ns > 0:
            future = Future()
            _tell_sleeping()
            wait_on_clock(node, executor, future, executor.group_of_caller(), left_ns * 1e-9,
                          lambda: future.set_result(None))
        return True

    def sleep_for(rel_time: Duration, context=None) -> bool:
        return sleep_until(clock.now() + rel_time, context)
    clock.sleep_until, clock.sleep_for = sleep_until, sleep_for


_wall_sleep = time.sleep


def host_wall_sleeps() -> None:
    """``time.sleep`` waits on the run's clock when a lockstep walk runs the caller (a hosted
    callback), and on the wall clock everywhere else: the host's own code, other threads."""
    time.sleep = _sleep


def _sleep(seconds: float) -> None:
    scheduler = getattr(getcurrent(), "scheduler", None)      # the walk's (hosting/executors/scheduler.py)
    executor = scheduler.owner if scheduler is not None else None
    if executor is not None and sys._getframe(1).f_globals.get("__name__", "").startswith("rclpy"):
        # rclpy's own polling (wait_for_service, wait_for_server): its process would poll the ROS
        # graph in wall time, and so does the host (what the run serves is ready at once).
        return _wall_sleep(seconds)
    node = None if executor is None else executor.running_node or next(iter(executor.get_nodes()), None)
    if node is None or not seconds > 0:
        return _wall_sleep(seconds)
    if not getattr(executor, "said_sleeps", False):
        executor.said_sleeps = True
        logger = node.get_logger()
        text = (f"a callback of {logger.name} called time.sleep({seconds:g}): hosted, a callback that sleeps is "
                f"set aside for that long on the run's clock while the others run, as its own process's other "
                f"threads would run them (docs/contract.md, \"Timeouts and sleeps\")")
        (logger.host_note if hasattr(logger, "host_note") else lambda line: print(f"composed-sim: {line}",
                                                                                     file=sys.stderr))(text)
    future = Future()
    _tell_sleeping()
    wait_on_clock(node, executor, future, executor.group_of_caller(), seconds, lambda: future.set_result(None))
