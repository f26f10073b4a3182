"""A service served in process and the responses handed to its clients.

Between the nodes of one hosting process the host hands a call over itself: the request (a copy,
as DDS would deliver it) goes into the service's queue (``ServiceEntry``), the lockstep walk runs
the service's callback in its place in the fixed order (``NodeServices``; a stock executor runs it
as a task), and the response (a copy) completes the client's future once the client's callback
group may run (``hand_over``), as rclpy's executors require.
"""
from __future__ import annotations

from collections import deque
from types import CoroutineType
from typing import Callable, Optional

from greenlet import getcurrent
from rclpy.executors import await_or_execute
from rclpy.node import Node
from rclpy.service import Service
from rclpy.task import Future

from composed_sim.ros.message_copy import new_message


class CallFuture(Future):
    """A call's future; awaiting it tells the lockstep executor what to wait for (rclpy's says
    nothing), and a callback blocked on it is woken directly (``waiters``), not by a done callback."""

    def __init__(self, *, executor=None):
        super().__init__(executor=executor)
        self.waiters: list = []

    def __await__(self):
        while self._pending():
            yield self
        return self.result()

    def _schedule_or_invoke_done_callbacks(self):
        super()._schedule_or_invoke_done_callbacks()
        waiters, self.waiters = self.waiters, []
        for wake in waiters:
            wake()


class HostedCallError(RuntimeError):
    """A hosted node's call that would wait forever in any process: the message says why."""


def hand_over(executor, group, work: Callable[[], None]) -> None:
    """Run ``work`` (completing a client's future) once ``group`` may run: the lockstep executor
    keeps the group's rule; for a stock one it runs now, as rclpy's own executor completes a
    future from whichever thread took the response, and the future's done callbacks become its
    tasks."""
    when_free = getattr(executor, "when_free", None)
    if when_free is not None:
        when_free(group, work)
    else:
        work()


def completing(future: Future, response) -> Callable[[], None]:
    """Work that completes ``future`` with ``response``, unless it was given up on."""
    return lambda: future.done() or future.cancelled() or future.set_result(response)


class NodeServices:
    """A node's services served in process, one entry of the lockstep walk: its requests waiting."""
    __slots__ = ("entries", "pending")

    def __init__(self):
        self.entries: list[ServiceEntry] = []
        self.pending = 0

    def serve_ready(self, executor, held) -> int:
        """Serve every waiting request whose service's group may run, service by service, until a
        callback is set aside (the walk that resumes it stops there); returns how many."""
        served, me = 0, getcurrent()
        for entry in self.entries:
            while entry.queue and not (held and entry.group in held):
                self.pending -= 1
                served += 1
                entry.serve_next(executor)
                if executor.scheduler.walker is not me:
                    return served
        return served


class ServiceEntry:
    """One service served in process: its queue of (request, reply) and what serves it."""
    __slots__ = ("name", "srv_type", "node", "group", "queue", "service", "_callback", "_owner", "on_outside")

    def __init__(self, name: str, srv_type, node: Node, group, owner: Optional[NodeServices],
                 service: Optional[Service] = None, callback: Optional[Callable] = None):
        """``owner``: the node's services the lockstep walk serves (None: a stock executor's tasks)."""
        self.name, self.srv_type, self.node, self.group = name, srv_type, node, group
        self.queue: deque = deque()
        self.service = service            # the rclpy Service (its DDS endpoint), or None: in process only
        self._callback = callback
        self._owner = owner
        self.on_outside: Optional[Callable[[], None]] = None   # an in-process one a client elsewhere wants
    @property
    def callback(self) -> Callable:
        # The service's current callback: the host's guard may have wrapped it since.
        return self.service.callback if self.service is not None else self._callback

    def submit(self, request, reply: Callable) -> None:
        """A request, whose response goes to ``reply(response)``."""
        if self._owner is not None:
            self.queue.append((request, reply))
            self._owner.pending += 1
        else:
            self.node.executor.create_task(self._serve_as_task, request, reply)

    def serve_next(self, executor) -> None:
        """The lockstep walk: run the callback on the oldest request."""
        request, reply = self.queue.popleft()
        executor.running_group, executor.running_node = self.group, self.node
        response = self.callback(request, new_message(self.srv_type.Response))
        if response.__class__ is CoroutineType:
            task = executor.start_coroutine(response, self.group, self.node)
            task.add_done_callback(lambda done: done.exception() is None and self._respond(executor, reply, done.result()))
        else:
            self._respond(executor, reply, response)

    async def _serve_as_task(self, request, reply: Callable) -> None:
        response = await await_or_execute(self.callback, request, new_message(self.srv_type.Response))
        self._respond(self.node.executor, reply, response)

    def _respond(self, executor, reply: Callable, response) -> None:
        if isinstance(response, self.srv_type.Response):
            reply(response)
            return
        watcher = getattr(executor, "watcher", None)
        if watcher is not None and (response is not None or watcher.owner_alive(self.node)):
            # rclpy's executor raises on it: the serving node's fault, as in its own process.
            watcher.node_failed(self.node, TypeError(
                f"service {self.name} returned {type(response).__name__}, not a {self.srv_type.__name__}.Response"))
