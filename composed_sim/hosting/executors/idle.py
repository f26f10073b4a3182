"""Waiting for work without taking it: the lockstep executor's idle wait.

When a walk finds nothing ready, the executor waits until something is (a message from another
process, a due timer, a guard condition) and then walks again, so that what arrived runs in the
walk's order, where a callback may be set aside. rclpy's ``spin_once`` would wait and then run
the first ready entity itself, outside that order.
"""
from __future__ import annotations

from contextlib import ExitStack
from typing import Optional

from rclpy.exceptions import InvalidHandle
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.waitable import NumberOfEntities


def wait_for_work(executor, timeout_sec: Optional[float]) -> None:
    """Wait up to ``timeout_sec`` (None: for ever) until an entity of ``executor``'s nodes is
    ready, or it is woken (an entity made, a shutdown)."""
    timeout_ns = -1 if timeout_sec is None else int(max(0.0, timeout_sec) * 1e9)
    with ExitStack() as held:
        handles = {"subscription": [], "timer": [], "client": [], "service": [], "guard_condition": []}
        directory = executor.services
        for node in executor.get_nodes():
            # A service served in process takes the requests of other processes as a tick starts
            # (hosting/calls/outside.py): one waiting there is not work for now.
            services = node.services if directory is None else [s for s in node.services if not directory.serves(s)]
            for kind, entities in (("subscription", node.subscriptions), ("timer", node.timers),
                                   ("client", node.clients), ("service", services),
                                   ("guard_condition", node.guards)):
                for entity in entities:
                    try:
                        held.enter_context(entity.handle)
                    except InvalidHandle:
                        continue
                    handles[kind].append(entity.handle)
        guards = [g for g in (executor._guard, executor._sigint_gc) if g is not None]
        for guard in guards:
            held.enter_context(guard.handle)
            handles["guard_condition"].append(guard.handle)
        # The waitables (the simulator's answer subscriptions, action endpoints) wait with the rest.
        waitables, extra = [], NumberOfEntities()
        for node in executor.get_nodes():
            for waitable in node.waitables:
                try:
                    held.enter_context(waitable)
                except InvalidHandle:
                    continue
                waitables.append(waitable)
                extra += waitable.get_num_entities()
        context = executor.context
        held.enter_context(context.handle)
        wait_set = _rclpy.WaitSet(len(handles["subscription"]) + extra.num_subscriptions,
                                  len(handles["guard_condition"]) + extra.num_guard_conditions,
                                  len(handles["timer"]) + extra.num_timers, len(handles["client"]) + extra.num_clients,
                                  len(handles["service"]) + extra.num_services, extra.num_events, context.handle)
        wait_set.clear_entities()
        for kind, kind_handles in handles.items():
            add = getattr(wait_set, f"add_{kind}")
            for handle in kind_handles:
                add(handle)
        for waitable in waitables:
            waitable.add_to_wait_set(wait_set)
        wait_set.wait(timeout_ns)


def readings_waiting(subscriptions, context, timeout_s: float = 0.0) -> list[bool]:
    """Which of ``subscriptions`` (of ``context``) have a message waiting, without taking it;
    ``timeout_s``: first wait up to that long until one has."""
    with ExitStack() as held:
        for sub in subscriptions:
            held.enter_context(sub.handle)
        held.enter_context(context.handle)
        wait_set = _rclpy.WaitSet(len(subscriptions), 0, 0, 0, 0, 0, context.handle)
        wait_set.clear_entities()
        for sub in subscriptions:
            wait_set.add_subscription(sub.handle)
        wait_set.wait(int(timeout_s * 1e9))
        ready = set(wait_set.get_ready_entities("subscription"))
    return [sub.handle.pointer in ready for sub in subscriptions]
