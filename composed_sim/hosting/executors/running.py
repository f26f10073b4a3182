"""Making the executor of a process's hosted nodes, and driving it: from the calling thread or in
a thread of its own (``Spinning``), and until nothing is ready (``run_until_idle``)."""
from __future__ import annotations

import inspect
import os
import threading
from typing import Callable, Iterable, Optional

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor

from composed_sim.hosting import HostError
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.process_hosting import EXECUTORS

SETTLE_ROUNDS = 1000        # bound on the looks that run what is left to do (a busy node cannot hang a tick)


def check_executor(kind: str) -> None:
    if kind not in EXECUTORS:
        raise HostError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")


def make_executor(kind: str, context: Context, robots: int = 1) -> Executor:
    """The executor of a process's nodes; ``robots``: how many robots' nodes it runs. rclpy's
    multi-threaded executor gets the threads of that many processes of their own (a pool of one
    per core each, started as callbacks need them): a callback blocked on a call holds one of its
    robot's, as in its own process, not one shared by every robot of this one."""
    if kind == "multi-threaded":
        return MultiThreadedExecutor(num_threads=robots * (os.cpu_count() or 2), context=context)
    if kind == "single-threaded":
        return SingleThreadedExecutor(context=context)
    if kind == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=context)
    check_executor(kind)
    return LockstepExecutor(context=context)


def driven_by_caller(kind: str, *, guarded: bool) -> bool:
    """Is an executor of this kind driven from the calling thread (``spin_once``) rather than
    spinning in a thread of its own? The lockstep executor by design; the EventsExecutor because
    its spin() in a background thread hung in our probes (docs/architecture.md); the
    single-threaded one where the callback guard must be able to interrupt a hung callback
    (``guarded``: a signal reaches only the main thread). The multi-threaded executor never: its
    callbacks run on its own threads, as it is made for."""
    return kind in ("lockstep", "events") or (guarded and kind == "single-threaded")


def spin_until_shutdown(executor: Executor) -> None:
    """An executor's spin() for a background thread: ends quietly when the executor is shut down."""
    try:
        executor.spin()
    except ExternalShutdownException:
        pass


class Spinning:
    """An executor and, once ``start_thread`` made it spin by itself, its thread; ``stop`` shuts the
    executor down, then waits for the thread."""

    def __init__(self, executor: Executor):
        self.executor = executor
        self.thread: Optional[threading.Thread] = None

    def start_thread(self, name: str = "executor") -> None:
        self.thread = threading.Thread(target=spin_until_shutdown, args=(self.executor,), name=name, daemon=True)
        self.thread.start()

    def stop(self, *, shutdown_timeout_s: Optional[float] = None, join_timeout_s: float = 5.0) -> None:
        self.executor.shutdown(timeout_sec=shutdown_timeout_s)
        if self.thread is not None:
            self.thread.join(timeout=join_timeout_s)


def shut_down(spinning: Optional[Spinning], nodes: Iterable, context: Optional[Context], **stop) -> None:
    """A process's hosted side ended in order: the executor stopped (``stop``: ``Spinning.stop``'s
    timeouts), then the nodes destroyed (anything with ``destroy_node``, else ``destroy``), then
    their context shut down."""
    if spinning is not None:
        spinning.stop(**stop)
    for node in nodes:
        (node.destroy_node if hasattr(node, "destroy_node") else node.destroy)()
    if context is not None and context.ok():
        rclpy.shutdown(context=context)


def is_idle(executor: Executor, callbacks_run: Optional[Callable[[], int]] = None) -> bool:
    """Run what is ready now; True when nothing was. A lockstep walk says how many callbacks it
    ran: when it sees every entity (``walk_covers_all``), or with nothing else to go by, a walk
    that runs none means idle. Else a stock pass must look too, and only ``callbacks_run`` (the
    callback guard's count) tells whether it ran one: idle after two passes that ran none (a stock
    executor's ``spin_once`` may come back empty once, to rebuild its wait set; each pass costs a
    wait set rebuilt over every entity). Without a count, one pass is all there is to do."""
    lockstep = isinstance(executor, LockstepExecutor)
    if lockstep and (executor.walk_covers_all or callbacks_run is None):
        return executor.dispatch_ready() == 0
    if callbacks_run is None:
        executor.spin_once(timeout_sec=0)
        return True
    for _ in range(2):
        before = callbacks_run()
        if lockstep and executor.dispatch_ready():
            return False
        executor.spin_once(timeout_sec=0)
        if callbacks_run() != before:
            return False
    return True


def run_until_idle(executor: Executor, callbacks_run: Optional[Callable[[], int]] = None,
                   rounds: int = SETTLE_ROUNDS) -> bool:
    """Run what is ready until nothing is (``is_idle``), at most ``rounds`` looks: a robot's chain
    of nodes may go on after its answer, and what it publishes belongs to the tick."""
    return any(is_idle(executor, callbacks_run) for _ in range(rounds))


def refuse_coroutines_for_events(nodes) -> None:
    """rclpy's EventsExecutor calls a callback without awaiting what it returns: an ``async def``
    callback would never run, in a process of its own too. Said before tick 0."""
    for node in nodes:
        for entity in (*node.subscriptions, *node.timers, *node.services):
            if inspect.iscoroutinefunction(entity.callback):
                raise HostError(f"{node.get_fully_qualified_name()} has an async def callback ({type(entity).__name__} "
                                f"{getattr(entity, 'topic_name', None) or getattr(entity, 'srv_name', '')}): rclpy's "
                                f"EventsExecutor never awaits it (in a process of its own too); choose another "
                                f"--executor (the default runs it)")
