"""Has a node's ROS graph changed? rcl's graph guard condition, polled through ctypes.

rcl triggers a node's graph guard condition whenever its participant's view of the ROS graph
changes (an endpoint or a node discovered or gone, in this process or another); rclpy does not
expose it. A wait set of its own with a timeout of 0 tells whether it was triggered since the last
look (a wait consumes the trigger). The structs are laid out as in rcl's ``wait.h`` and rcutils'
``allocator.h`` that ship with the ROS wheels; rclpy's extension module has loaded librcl already.
"""
from __future__ import annotations

import ctypes
from typing import Callable

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


def guard_condition_poll(node: Node) -> Callable[[], bool]:
    """``changed()``: has ``node``'s graph changed since the last call (the first call: since the
    node was created)? Any doubt (a failed wait) counts as a change."""
    with node.handle:
        guard = _rcl.rcl_node_get_graph_guard_condition(node.handle.pointer)
    wait_set = _rcl.rcl_get_zero_initialized_wait_set()
    with node.context.handle:
        if guard is None or _rcl.rcl_wait_set_init(ctypes.byref(wait_set), 0, 1, 0, 0, 0, 0, node.context.handle.pointer,
                                                   _rcutils.rcutils_get_default_allocator()) != _RET_OK:
            return lambda: True
    ref = ctypes.byref(wait_set)

    def changed() -> bool:
        if _rcl.rcl_wait_set_clear(ref) != _RET_OK or _rcl.rcl_wait_set_add_guard_condition(ref, guard, None) != _RET_OK:
            return True
        if _rcl.rcl_wait(ref, 0) != _RET_OK:     # RCL_RET_TIMEOUT: nothing triggered
            return False
        return bool(wait_set.guard_conditions[0])
    changed.wait_set = wait_set                  # kept alive with the closure
    return changed
