"""The lockstep executor's tasks, and what it tells the host about the work it runs.

A task is what rclpy's executors run besides entity callbacks: a future's done callback, a
``create_task``, an ``async def`` callback's coroutine, an action's execution. Each belongs to the
robot whose callback made it (or whose node it serves), so that its failure is that robot's, as
its process's crash would be.
"""
from __future__ import annotations

from types import CoroutineType
from typing import Optional

from rclpy.node import Node
from rclpy.task import Future, Task


class CallbackWatcher:
    """What the executor tells the host about the work it runs (the callback guard implements it:
    hosting/guard/callback_guard.py); this default tells nobody and blames nobody."""

    def owner(self) -> Optional[str]:
        """The robot whose callback runs now (a task it makes is its own)."""
        return None

    def robot_of(self, node: Node) -> Optional[str]:
        """The robot ``node`` belongs to (None: not a robot's)."""
        return None

    def task_started(self, robot: Optional[str]) -> bool:
        """A task of ``robot`` starts or resumes: False if it must not (its robot failed)."""
        return True

    def task_ended(self) -> None:
        """The task that started last stopped (done, or waiting)."""

    def task_failed(self, robot: Optional[str], error: BaseException) -> bool:
        """A task of ``robot`` raised: True if the host has dealt with it (the robot failed)."""
        return False

    def owner_alive(self, node: Node) -> bool:
        """Is the robot (or run-wide node) that ``node`` belongs to still running?"""
        return True

    def node_failed(self, node: Node, error: BaseException) -> None:
        """``node`` did what would end its process: the host fails what it belongs to."""
        raise error

    def set_aside(self) -> object:
        """The running callback is set aside: forget it as running; what ``take_back`` needs."""
        return None

    def take_back(self, state: object) -> None:
        """The callback set aside with ``state`` runs again."""


class HostedTask(Task):
    """A task of the lockstep executor: a function, or a coroutine stepped until it is done; the
    robot it belongs to, and the mutually exclusive group it holds until done (an ``async def``
    callback's, as rclpy holds it)."""

    def __init__(self, handler, args=None, kwargs=None, executor=None, robot: Optional[str] = None, node=None):
        super().__init__(handler, args, kwargs, executor)
        self.robot = robot
        self.node = node             # the node whose callback made it, where known
        self.group = None

    def __await__(self):
        # Yields itself, so that the awaiting task is stepped again when this one is done.
        while self._pending():
            yield self
        return self.result()

    def __call__(self):
        """Run the function, or step the coroutine once; returns what the coroutine awaits now
        (None when done, or when it awaits something that does not say what it is)."""
        if not self._pending() or self._executing:
            return None
        self._executing = True
        try:
            handler = self._handler
            if handler.__class__ is not CoroutineType:
                try:
                    self.set_result(handler(*self._args, **self._kwargs))
                except Exception as e:           # noqa: BLE001 - a task's failure is its result
                    self.set_exception(e)
                self._complete_task()
                return None
            try:
                return handler.send(None)
            except StopIteration as done:
                self.set_result(done.value)
            except Exception as e:               # noqa: BLE001 - a task's failure is its result
                self.set_exception(e)
            self._complete_task()
            return None
        finally:
            self._executing = False


def awaits_future(awaited) -> bool:
    """Did a coroutine's step say it awaits this future (ours do; rclpy's yield nothing)?"""
    return isinstance(awaited, Future)
