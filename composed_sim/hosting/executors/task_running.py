"""The lockstep executor's tasks and callback groups (a part of ``LockstepExecutor``,
hosting/executors/lockstep.py): futures' done callbacks, ``create_task`` and ``async def`` callbacks
run as tasks, first in, first out, after the callback that made them ready; a callback set aside
while it waits (hosting/executors/scheduler.py); the mutually exclusive groups held meanwhile."""
from __future__ import annotations

from collections import deque
from types import CoroutineType
from typing import Callable, Optional

from greenlet import GreenletExit, getcurrent
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.task import Future, Task

from composed_sim.hosting.executors.tasks import HostedTask, awaits_future

_UNSET = object()


class TaskRunning:
    # --- tasks ----------------------------------------------------------------------------------

    def create_task(self, callback, *args, **kwargs) -> Task:
        """A task run by the walks, after the callback that made it, in the order made."""
        task = HostedTask(callback, args, kwargs, executor=self, robot=self.watcher.owner(), node=self.running_node)
        self.scheduler.tasks.append(task)
        return task

    def start_coroutine(self, coroutine, group, node: Optional[Node] = None) -> HostedTask:
        """An ``async def`` callback's coroutine, run as a task of ``node``'s robot: its first step
        now; its group, if mutually exclusive, held until it is done."""
        robot = self.watcher.robot_of(node) if node is not None else self.watcher.owner()
        task = HostedTask(coroutine, executor=self, robot=robot, node=node or self.running_node)
        if isinstance(group, MutuallyExclusiveCallbackGroup):
            self._held.add(group)
            task.group = group
        self._run_task(task)
        return task

    def _run_task(self, task: HostedTask, polled: bool = False) -> None:
        watcher = self.watcher
        self.running_node = task.node
        if not watcher.task_started(task.robot):
            task.cancel()
            self._release(task.group)
            return
        try:
            awaited = task()
        except (GreenletExit, KeyboardInterrupt):
            raise
        except BaseException as e:               # noqa: BLE001 - a hung or exiting task (ControllerHung, SystemExit)
            task.set_exception(e)
            awaited = None
        finally:
            watcher.task_ended()
        if not task.done():
            if awaits_future(awaited):           # stepped again when that is done
                awaited.add_done_callback(lambda _: self.scheduler.tasks.append(task))
            else:
                self._polled_tasks.append(task)
                if polled:
                    return                       # still waiting on the same unknown thing: no progress
        self._ran += 1
        if task.done():
            self._release(task.group)
            if task._exception is not None and not task._exception_fetched \
                    and not watcher.task_failed(task.robot, task.exception()):
                raise task.exception()

    # --- callback groups ------------------------------------------------------------------------

    def _release(self, group) -> None:
        if group is None:
            return
        self._held.discard(group)
        waiting = self._after_release.pop(group, None)
        if waiting:
            self.scheduler.tasks.extend(waiting)

    def when_free(self, group, work: Callable[[], None]) -> None:
        """Run ``work`` (a task) once ``group`` may run a callback: next, or once it is released."""
        if group in self._held:
            self._after_release.setdefault(group, deque()).append(work)
        else:
            self.scheduler.tasks.append(work)

    def run_callback(self, callback: Callable[[], object], group) -> None:
        """A callback the host hands over (a delivered run-wide message) runs as a task once its
        callback group may run; an ``async def``'s coroutine holds the group until it is done."""
        def run() -> None:
            self.running_group = group
            result = callback()
            if result.__class__ is CoroutineType:
                self.start_coroutine(result, group)
        self.when_free(group, run)

    def group_of_caller(self):
        """The callback group of the callback that calls (None for a task)."""
        group = getattr(getcurrent(), "callback_group", _UNSET)
        return self.running_group if group is _UNSET else group

    # --- waiting inside a callback --------------------------------------------------------------

    def can_wait(self) -> bool:
        """Is the caller a callback this executor's walk runs (so it can be set aside)?"""
        return self.scheduler.in_walk()

    def wait_for(self, future: Future, group=None) -> None:
        """Set the calling callback aside until ``future`` is done; ``group``, the callback's
        callback group, is held meanwhile if mutually exclusive."""
        getcurrent().callback_group = group      # its stack is its own from now on
        hold = isinstance(group, MutuallyExclusiveCallbackGroup) and group not in self._held
        if hold:
            self._held.add(group)
        state, node = self.watcher.set_aside(), self.running_node
        try:
            self.scheduler.wait(future)
        finally:
            self.watcher.take_back(state)
            self.running_node = node             # resumed: the callback's node again
            if hold:
                self._release(group)

    def _step_polled(self, me) -> None:
        """Step again the coroutines that await what does not say what it is (rclpy's futures)."""
        polled, self._polled_tasks = self._polled_tasks, []
        for task in polled:
            self._run_task(task, polled=True)
            if self.scheduler.walker is not me:
                return
        self._run_tasks()

    def _run_tasks(self) -> None:
        """Run the ready tasks, first in, first out, and the ones they make ready. A task is a
        ``HostedTask`` or a plain callable the host queued (a delivered message, a response);
        one that returns a coroutine (an ``async def`` subscription callback) starts it."""
        tasks, scheduler, me = self.scheduler.tasks, self.scheduler, getcurrent()
        while tasks:
            task = tasks.popleft()
            self.running_group = self.running_node = None
            if task.__class__ is HostedTask:
                self._run_task(task)
            else:
                result = task()
                self._ran += 1
                if result.__class__ is CoroutineType:
                    self.start_coroutine(result, None)
            if scheduler.walker is not me:
                break
