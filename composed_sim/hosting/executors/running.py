"""Making the executor of a process's hosted nodes, and driving it."""
from __future__ import annotations

from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor

from composed_sim.hosting import HostError
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.options import EXECUTORS


def check_executor(kind: str) -> None:
    if kind not in EXECUTORS:
        raise HostError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")


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


def spin_until_shutdown(executor: Executor) -> None:
    """An executor's spin() for a background thread: ends quietly when the executor is shut down."""
    try:
        executor.spin()
    except ExternalShutdownException:
        pass
