"""Has a node's ROS graph changed? rcl's graph guard conditions, waited on through ctypes.

rcl triggers a node's graph guard condition whenever its participant's view of the ROS graph
changes (an endpoint or a node discovered or gone, in this process or another); rclpy does not
expose it. A thread of its own waits on the graph guard conditions of the process's participants
(a wait consumes the triggers) and counts each one's changes; the tick reads the counts. Asking
rcl instead with a timeout of 0 on every tick cost CPU and a timer-slack sleep per participant,
every tick (docs/speed.md). The
structs are laid out as in rcl's ``wait.h`` and rcutils' ``allocator.h`` that ship with the ROS
wheels; rclpy's extension module has loaded librcl already.
"""
from __future__ import annotations

import ctypes
import threading
from typing import Callable, Optional, Sequence

from rclpy.guard_condition import GuardCondition
from rclpy.node import Node

_RET_OK = 0


class _Allocator(ctypes.Structure):          # rcutils_allocator_t
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p), ("reallocate", ctypes.c_void_p),
                ("zero_allocate", ctypes.c_void_p), ("state", ctypes.c_void_p)]


class _WaitSet(ctypes.Structure):            # rcl_wait_set_t
    _fields_ = [("subscriptions", ctypes.c_void_p), ("size_of_subscriptions", ctypes.c_size_t),
                ("guard_conditions", ctypes.POINTER(ctypes.c_void_p)), ("size_of_guard_conditions", ctypes.c_size_t),
                ("timers", ctypes.c_void_p), ("size_of_timers", ctypes.c_size_t),
                ("clients", ctypes.c_void_p), ("size_of_clients", ctypes.c_size_t),
                ("services", ctypes.c_void_p), ("size_of_services", ctypes.c_size_t),
                ("events", ctypes.c_void_p), ("size_of_events", ctypes.c_size_t),
                ("impl", ctypes.c_void_p)]


_rcl = ctypes.CDLL("librcl.so")
_rcutils = ctypes.CDLL("librcutils.so")
_rcutils.rcutils_get_default_allocator.restype = _Allocator
_rcl.rcl_get_zero_initialized_wait_set.restype = _WaitSet
_rcl.rcl_node_get_graph_guard_condition.argtypes = [ctypes.c_void_p]
_rcl.rcl_node_get_graph_guard_condition.restype = ctypes.c_void_p
_rcl.rcl_wait_set_init.argtypes = [ctypes.POINTER(_WaitSet)] + [ctypes.c_size_t] * 6 + [ctypes.c_void_p, _Allocator]
_rcl.rcl_wait_set_clear.argtypes = [ctypes.POINTER(_WaitSet)]
_rcl.rcl_wait_set_add_guard_condition.argtypes = [ctypes.POINTER(_WaitSet), ctypes.c_void_p,
                                                  ctypes.POINTER(ctypes.c_size_t)]
_rcl.rcl_wait.argtypes = [ctypes.POINTER(_WaitSet), ctypes.c_int64]
_rcl.rcl_wait_set_fini.argtypes = [ctypes.POINTER(_WaitSet)]


class GraphChanges:
    """How often each of some nodes' ROS graph has changed (one node per participant: the graph
    is the participant's), counted by a thread that blocks on their graph guard conditions and
    on one of its own that ``close`` triggers. If rcl fails it, every look counts as a change."""

    def __init__(self, nodes: Sequence[Node]):
        self.counts = [1] * len(nodes)          # the first look: changed since the node was created
        self._broken = False
        self._closed = False
        self._thread: Optional[threading.Thread] = None
        context = nodes[0].context
        self._wake = GuardCondition(None, None, context)
        guards = []
        for node in nodes:
            with node.handle:
                guards.append(_rcl.rcl_node_get_graph_guard_condition(node.handle.pointer))
        with self._wake.handle:
            guards.append(self._wake.handle.pointer)
        self._wait_set = _rcl.rcl_get_zero_initialized_wait_set()
        with context.handle:
            if None in guards or _rcl.rcl_wait_set_init(
                    ctypes.byref(self._wait_set), 0, len(guards), 0, 0, 0, 0, context.handle.pointer,
                    _rcutils.rcutils_get_default_allocator()) != _RET_OK:
                self._broken = True
                return
        self._thread = threading.Thread(target=self._watch, args=(guards,), name="graph changes", daemon=True)
        self._thread.start()

    def poll(self, k: int) -> Callable[[], bool]:
        """``changed()``: has node k's graph changed since the last call (the first call: since
        the node was created)?"""
        counts, seen = self.counts, [0]

        def changed() -> bool:
            count = counts[k]
            if count == seen[0] and not self._broken:
                return False
            seen[0] = count
            return True
        return changed

    def _watch(self, guards: list) -> None:
        ref, n = ctypes.byref(self._wait_set), len(self.counts)
        while not self._closed:
            if _rcl.rcl_wait_set_clear(ref) != _RET_OK or any(
                    _rcl.rcl_wait_set_add_guard_condition(ref, guard, None) != _RET_OK for guard in guards):
                break
            # No timeout: until a graph changes or ``close`` (ctypes lets the GIL go meanwhile).
            if _rcl.rcl_wait(ref, -1) != _RET_OK:
                break
            for k in range(n):
                if self._wait_set.guard_conditions[k]:
                    self.counts[k] += 1
        self._broken = not self._closed

    def close(self) -> None:
        """Stop the thread (before the nodes' contexts shut down)."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not None:
            self._wake.trigger()
            self._thread.join()
            _rcl.rcl_wait_set_fini(ctypes.byref(self._wait_set))
        self._wake.destroy()
