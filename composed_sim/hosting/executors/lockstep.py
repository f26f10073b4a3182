"""The lockstep executor: every hosted node's callbacks in one fixed order, with the execution
semantics of a process of its own under rclpy's MultiThreadedExecutor.

The stock executors rebuild a wait set over every entity of every node on each spin: with
thousands of hosted nodes that dominates the tick. In a lockstep tick the work is known: the
simulator publishes every robot's sensors, and inside one DDS participant a published message is
ready to take at once. So this executor walks its nodes' entities in a fixed order
(hosting/executors/walk_entries.py), takes what is ready and runs the callbacks; what a callback
publishes or calls is picked up by the same walk. One message per sensor subscription and walk (a
robot's sensors come once per tick), every ready message of any other. Only what the walk cannot
take (a user's guard condition, a waitable of an unknown kind) waits for the ordinary wait set,
when a walk finds nothing.

What a node's own process gives it, given here in that one order (docs/contract.md, "What a
node may do"):

- ``async def`` callbacks (subscriptions, timers, services, done callbacks) run as tasks: a
  coroutine that awaits what is not done is stepped again once it is;
- futures' done callbacks and ``create_task`` run as tasks (hosting/executors/tasks.py), first in,
  first out, after the callback that made them ready;
- a callback may block on a call (``Client.call``, an action's ``send_goal``, a rate's
  ``sleep``): it is set aside (hosting/executors/scheduler.py) while the walk runs what it waits for;
- callback groups: while a callback of a mutually exclusive group waits, no other callback of the
  group starts, and a response is handed to a client only when the client's group may run, as
  under the MultiThreadedExecutor; a reentrant group runs anything;
- calls between its nodes are served in process (hosting/calls/directory.py).

Callbacks run one at a time, in that order: runs are deterministic and a plugin needs no locks.
"""
from __future__ import annotations

from collections import deque
from types import CoroutineType
from typing import Callable, Optional

from greenlet import getcurrent
from rclpy.event_handler import EventHandler
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future

from composed_sim.hosting.executors.scheduler import Scheduler
from composed_sim.hosting.executors.task_running import TaskRunning
from composed_sim.hosting.executors.tasks import CallbackWatcher, HostedTask
from composed_sim.hosting.executors.idle import wait_for_work
from composed_sim.hosting.executors.walk_entries import (BATCH, OWN_GROUP, POLLED, SERVICE, TIMER, WAITABLE, WalkEntry,
                                                         walk_entries)

class LockstepExecutor(TaskRunning, SingleThreadedExecutor):
    def __init__(self, *, context=None, watcher: Optional[CallbackWatcher] = None) -> None:
        super().__init__(context=context)
        self.scheduler = Scheduler(self)
        self.watcher = watcher or CallbackWatcher()
        self.services = None                      # its ServiceDirectory (hosting/calls/directory.py), if hosted
        self.on_entities_changed: Optional[Callable[[Node], None]] = None   # the host hosts what is new
        self.before_walk: Optional[Callable[[], None]] = None   # a controller process's wait for a tick's readings
        self.running_group = None                 # the callback group of the callback the walk runs
        self.running_node: Optional[Node] = None  # and its node (None: a task's)
        self._ordered_nodes: list[Node] = []
        self._entities: Optional[list[WalkEntry]] = None   # rebuilt when entities change
        self._service_entities: Optional[list[WalkEntry]] = None
        self._covers_all: Optional[bool] = None
        self._changed: list[Node] = []            # nodes that created or destroyed entities
        self._held: set = set()                   # mutually exclusive groups whose callback waits
        self._after_release: dict[object, deque] = {}   # per held group: what waits for it
        self._polled_tasks: list[HostedTask] = []     # coroutines that await something unknown
        # Where the walk is: a walker that takes over from one whose callback waits goes on from
        # there (every walker of one ``dispatch_ready`` shares it), not from the start.
        self._cursor = None
        self._ran = 0                             # callbacks and tasks run (what a walk reports)
        # Callbacks in rclpy.spin_once(node) (hosting/sim_time/spins.py): per node, what to complete
        # once another callback of it has run.
        self._spinners: dict[Node, list[Future]] = {}

    # --- nodes ----------------------------------------------------------------------------------

    def add_node(self, node: Node) -> bool:
        added = super().add_node(node)
        if added:
            self._ordered_nodes.append(node)
            self._entities = self._service_entities = self._covers_all = None
            # A node that creates or destroys an entity wakes its executor: before the next walk
            # the host hosts what is new as it hosted what the node's constructor made.
            node._wake_executor = lambda node=node: self._entities_changed(node)
        return added

    def remove_node(self, node: Node) -> None:
        super().remove_node(node)
        if node in self._ordered_nodes:
            self._ordered_nodes.remove(node)
        self._entities = self._service_entities = self._covers_all = None

    def _entities_changed(self, node: Node) -> None:
        if node not in self._changed:
            self._changed.append(node)
        self.wake()

    def wake(self) -> None:
        self._entities = self._service_entities = self._covers_all = None
        super().wake()

    # --- spinning -------------------------------------------------------------------------------

    def spin_once(self, timeout_sec: Optional[float] = None) -> None:
        if self.before_walk is not None:
            self.before_walk()
        if self.dispatch_ready() != 0:
            return
        if self.walk_covers_all:
            # Nothing ready: wait until something is (a message from another process, a timer),
            # then take it in the walk's order.
            wait_for_work(self, timeout_sec)
            if self.before_walk is not None:
                self.before_walk()
            self.dispatch_ready()
            return
        # What the walk cannot take, through rclpy's wait set: in a walker too, so that a callback
        # run there may wait.
        self.scheduler.run(lambda: SingleThreadedExecutor.spin_once(self, timeout_sec))

    def spin_once_until_future_complete(self, future: Future, timeout_sec=None) -> None:
        """rclpy's ``spin_until_future_complete`` steps this: one ``spin_once`` (its walk), not
        rclpy's wait set alone, which would never run the walk's tasks."""
        future.add_done_callback(lambda _: self.wake())
        self.spin_once(getattr(timeout_sec, "timeout", timeout_sec))

    @property
    def walk_covers_all(self) -> bool:
        """Does the walk see every entity its nodes have? Then a walk that runs nothing means that
        nothing is ready. (A QoS event handler, which rclpy gives most endpoints, only reports a
        mismatch: it can wait for the next pass over the wait set.) Known afresh whenever the
        entities change."""
        if self._covers_all is None:
            services = self.services
            self._covers_all = not self._changed and all(
                all(services is not None and services.serves(s) for s in node.services)
                and all(services is not None and services.takes_responses(cl) for cl in node.clients)
                and not any(True for _ in node.guards)
                and all(hasattr(w, "dispatch_ready") or isinstance(w, EventHandler)
                        or (services is not None and services.polls(w)) for w in node.waitables)
                for node in self._ordered_nodes)
        return self._covers_all

    def dispatch_ready(self) -> int:
        """Take and handle every message, request and response ready now, fire every timer due
        now, and run the tasks they make ready, in the fixed order; returns how many callbacks
        and tasks ran."""
        before = self._ran
        self._cursor = None
        self.scheduler.run(self._walk)
        return self._ran - before

    def serve_handed_over(self) -> int:
        """Only what the host handed over (tasks: delivered messages, responses; requests queued
        at the services), not the subscriptions and timers; returns how many ran."""
        before = self._ran
        self._cursor = None
        self.scheduler.run(lambda: self._walk(services_only=True))
        return self._ran - before

    def notify_after_callback_of(self, node: Node, future: Future) -> None:
        """Complete ``future`` once the walk has run a callback of ``node`` (a subscription's,
        a timer's, a service's): what ``rclpy.spin_once(node)`` inside a callback waits for."""
        self._spinners.setdefault(node, []).append(future)

    def _callback_of_ran(self, node: Node) -> None:
        for future in self._spinners.pop(node, ()):
            if not future.done():
                future.set_result(None)

    def shutdown(self, timeout_sec: Optional[float] = None) -> bool:
        self.scheduler.close()
        return super().shutdown(timeout_sec)

    # --- the walk -------------------------------------------------------------------------------

    def _build_entities(self) -> list[WalkEntry]:
        """What a walk needs of each entity, resolved once (hosting/executors/walk_entries.py)."""
        changed, self._changed = self._changed, []
        if changed:
            self._covers_all = None          # it was known while they were pending
        if self.on_entities_changed is not None:
            for node in changed:
                self.on_entities_changed(node)
        return walk_entries(self._ordered_nodes, self.services)

    def _start_walk(self, services_only: bool) -> None:
        """A new walk's cursor, over every entry or only the services' (``serve_handed_over``)."""
        entities = self._entities
        if entities is None:
            entities = self._entities = self._build_entities()
        if services_only:
            entities = self._service_entities
            if entities is None:
                entities = self._service_entities = [e for e in self._entities if e.kind is SERVICE]
        self._cursor = iter(entities)

    def _walk(self, services_only: bool = False) -> None:
        if self._cursor is None:
            self._start_walk(services_only)
        scheduler = self.scheduler
        tasks, held = scheduler.tasks, self._held
        coroutine = CoroutineType
        me = getcurrent()       # the walk stops once another greenlet walks (set aside in a callback)
        spinners = self._spinners
        ran = -1
        skip = 0
        self._run_tasks()
        if scheduler.walker is not me:
            return
        for entity, handle, kind, raw, message_only, once, inbox, group, node in self._cursor:
            if skip:                               # a batch's subscriptions, handled by it this walk
                skip -= 1
                continue
            if held and group in held:             # a callback of its group waits: later
                continue
            if spinners:
                ran = self._ran
            result = None
            if kind is BATCH:
                result, skip = self._run_batch(entity, inbox, once, group)
            elif kind is WAITABLE:
                self._ran += entity.dispatch_ready()
                continue
            elif kind is SERVICE:
                if not entity.pending:
                    continue
                self._ran += entity.serve_ready(self, held)
            elif kind is POLLED:
                self._ran += self.services.poll(entity, node, self)
            elif kind is OWN_GROUP:
                result = self._run_in_own_group(entity)
            elif kind is TIMER:
                try:
                    with handle:
                        if not handle.is_timer_ready():
                            continue
                        handle.call_timer()
                except InvalidHandle:              # destroyed since the entries were made (rclpy's way)
                    continue
                self.running_group, self.running_node = group, node
                result = entity.callback()
                self._ran += 1
            else:
                self.running_group, self.running_node = group, node
                result = self._take(entity, handle, kind, raw, message_only, once, inbox)
            if result.__class__ is coroutine:
                self.start_coroutine(result, group, node)
            if scheduler.walker is not me:         # set aside in a callback, resumed later: stop
                return
            if spinners and self._ran != ran and node in spinners:
                self._callback_of_ran(node)
            if tasks:
                self._run_tasks()
                if scheduler.walker is not me:
                    return
        self._run_tasks()
        if self._polled_tasks and scheduler.walker is me:
            self._step_polled(me)

    def _run_in_own_group(self, entry: WalkEntry):
        """A timer or subscription whose callback group is the node's own kind: taken and run only
        once the group allows it (``can_execute``, then ``beginning_execution``), and the group told
        when it ended (``ending_execution``), as rclpy's executors do; a timer the group holds back
        stays ready for a later walk."""
        entity, handle, kind, raw, message_only, _, inbox, group, _ = entry
        if kind is TIMER:
            try:
                with handle:
                    if not handle.is_timer_ready() or not group.can_execute(entity):
                        return None
                    if not group.beginning_execution(entity):
                        return None
                    handle.call_timer()
            except InvalidHandle:
                return None
            take = entity.callback
        elif (inbox is not None and inbox.queue) or inbox is None or inbox.dds_may_hold():
            if not group.can_execute(entity) or not group.beginning_execution(entity):
                return None
            take = lambda: self._take(entity, handle, kind, raw, message_only, True, inbox)     # noqa: E731 - a closure over the entity, built in the walk's hot loop
        else:
            return None
        self.running_group, self.running_node = group, entry.node
        try:
            result = take()
        finally:
            group.ending_execution(entity)
        self._ran += kind is TIMER
        return result

    def _take(self, entity, handle, msg_type, raw, message_only, once, inbox):
        """A subscription's ready messages: from its in-process inbox (its callback takes the
        message alone), then from DDS; returns its last callback's result."""
        if inbox is None:
            return self._take_from_dds(entity, handle, msg_type, raw, message_only, once, None)
        result = None
        if inbox.queue:
            result = entity.callback(inbox.take())
            self._ran += 1
            while not once and inbox.queue and result.__class__ is not CoroutineType:
                result = entity.callback(inbox.take())
                self._ran += 1
        # DDS is asked only when it may hold a message too (an empty take costs a call into rcl per
        # subscription and walk).
        if result.__class__ is not CoroutineType and inbox.dds_may_hold():
            result = self._take_from_dds(entity, handle, msg_type, raw, message_only, once, inbox)
        return result

    def _run_batch(self, callback, inboxes, count: int, group) -> tuple[object, int]:
        """A controller's sensor messages of the tick, all waiting in process and none in DDS: one
        call with all of them, instead of one per subscription (the ``count`` entities that follow,
        which handle them one by one otherwise). Returns the callback's result and how many
        entities to skip (0: not all waiting, the subscriptions take them one by one)."""
        for box in inboxes:
            if not box.queue or box.dds_may_hold():
                return None, 0
        self.running_group = group
        result = callback([box.take() for box in inboxes])
        self._ran += count
        return result, count

    def _take_from_dds(self, entity, handle, msg_type, raw, message_only, once, inbox):
        """One message (``once``) or every message DDS holds for a subscription, until a
        callback returns a coroutine (started by the walk, which takes the rest later)."""
        while True:
            try:
                with handle:
                    taken = handle.take_message(msg_type, raw)
            except InvalidHandle:                  # destroyed by a callback of this walk
                return None
            if taken is None:
                if inbox is not None:
                    inbox.emptied()
                return None
            result = entity.callback(taken[0]) if message_only else entity.callback(*taken)
            self._ran += 1
            if once or result.__class__ is CoroutineType:
                return result
