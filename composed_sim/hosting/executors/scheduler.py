"""One logical thread for every hosted callback: a callback that waits is set aside, not blocked.

A node in a process of its own may block in a callback until something else has run: a
``Client.call()`` in a reentrant callback group waits while the executor's other threads run the
service and hand back its response. Hosted by the hundred, the nodes' callbacks must run in an
order that does not depend on threads, or runs would differ from one another. So the executor's
walks run in a greenlet (a stack of their own, switched to and from explicitly, never
preempted): when a callback has to wait (``wait``), its stack is set aside as it is, a fresh
greenlet takes over the walk, and the set-aside stack resumes, from the same point, as a task of
the walk that completes what it waited for. Only one stack runs at a time, switches happen only
where a callback waits, and everything runs in the walk's fixed order: runs stay identical.

Callbacks that never wait cost nothing more: they run inline in the walk.
"""
from __future__ import annotations

from collections import deque
from typing import Callable, Optional

from greenlet import GreenletExit, error, getcurrent, greenlet


_TAKE_OVER = object()       # what a waiting walker tells ``run``: another must go on


class Scheduler:
    """The walks of one executor, and the callbacks set aside while they wait."""

    def __init__(self, owner=None):
        self.owner = owner                                    # its executor
        self.tasks: deque[Callable[[], None]] = deque()     # ready work, first in, first out
        self._home: Optional[greenlet] = None                 # who asked for the walk (the host's loop)
        self.walker: Optional[greenlet] = None                # the greenlet that walks now
        self._walk: Callable[[], None] = lambda: None
        self._set_aside: list[greenlet] = []                  # waiting, oldest first
        self._idle: list[greenlet] = []                       # walkers done with a stale walk, for reuse

    # --- the host's side ----------------------------------------------------------------------

    def run(self, walk: Callable[[], None]) -> None:
        """Run ``walk`` in the walker greenlet; a callback of it that waits is set aside and the
        walk goes on without it."""
        self._home, self._walk = getcurrent(), walk
        while True:
            walker = self.walker
            if walker is None or walker.dead:
                walker = self.walker = self._new_walker()
            if walker.switch() is not _TAKE_OVER:
                return
            # A callback of the walk waits: a fresh walker goes on with it, made here, where the
            # stack is shallow (a greenlet starts as deep as the one that first switches to it).
            self.walker = None

    def _new_walker(self) -> greenlet:
        if self._idle:                     # a greenlet costs more to make than to switch to
            walker = self._idle.pop()
            walker.parent = self._home
            return walker
        walker = greenlet(self._walker_main, parent=self._home)
        walker.scheduler = self            # what ``in_walk`` looks for
        return walker

    def _walker_main(self) -> None:
        me = getcurrent()
        while True:
            self._walk()
            if self.walker is not me:
                # Set aside in a walk, resumed by a later one: this walk's stack has served its
                # purpose; back to the walker that resumed it, until reused as a walker.
                if hasattr(me, "callback_group"):
                    del me.callback_group
                self._idle.append(me)
                me.parent.switch()
                continue
            self._home.switch()

    def close(self) -> None:
        """End every set-aside callback (its ``finally`` blocks run now, not at some later garbage
        collection), then the walker."""
        for waiting in (*reversed(self._set_aside), self.walker, *self._idle):
            if waiting is not None and not waiting.dead and waiting is not getcurrent():
                try:
                    waiting.throw(GreenletExit)
                except error:       # of another thread (an executor spun in a thread of its own)
                    pass
        self._set_aside.clear()
        self._idle.clear()
        self.tasks.clear()
        self.walker = None

    # --- the walk's side ------------------------------------------------------------------------

    def in_walk(self) -> bool:
        """Is the caller a callback run by a walk (so that it can be set aside)?"""
        return getattr(getcurrent(), "scheduler", None) is self

    def wait(self, future) -> None:
        """Set the calling callback aside until ``future`` is done (an rclpy ``Future``); the walk
        goes on meanwhile. Only for a caller that is ``in_walk``."""
        if future.done() or future.cancelled():
            return
        me = getcurrent()
        self._set_aside.append(me)
        wake = lambda: self.tasks.append(lambda: self._resume(me))     # noqa: E731 - a closure over the task, one expression
        waiters = getattr(future, "waiters", None)
        if waiters is not None:            # a future of ours wakes its waiters itself, without a task
            waiters.append(wake)
        else:
            future.add_done_callback(lambda _: wake())
        if me is self.walker:
            self._home.switch(_TAKE_OVER)
        else:
            self.walker.switch()      # a resumed callback waits again: back to the walk that resumed it

    def _resume(self, waiting: greenlet) -> None:
        if waiting.dead or waiting not in self._set_aside:
            return
        self._set_aside.remove(waiting)
        waiting.parent = getcurrent()  # when its old walk ends, control comes back here
        waiting.switch()
