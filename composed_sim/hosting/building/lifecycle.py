"""Lifecycle nodes (``rclpy.lifecycle``) hosted as their own process runs them.

A lifecycle node creates its publishers, subscriptions and timers in its transitions
(``on_configure``), not in its constructor, and publishes only while active. The host hosts what
a transition creates as it hosts what a constructor creates (hosting/hosted_block.py), serves the
node's lifecycle services (``~/change_state``, ``~/get_state``, …) in process like any service,
and starts the node itself before tick 0 when its world-file entry says ``lifecycle: autostart``
(configure, then activate, as a lifecycle manager's autostart does). Whether a robot answers on
``cmd_vel`` is checked once its nodes had their chance to become active: at tick 0, after the
run-wide nodes' part of it (a lifecycle manager's transitions).
"""
from __future__ import annotations

from typing import Optional

from lifecycle_msgs.msg import State
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node

AUTOSTART = "autostart"      # the world file's ``lifecycle:`` value (world/robot_groups.py)


class LifecycleError(Exception):
    """A lifecycle node could not be brought up as its world file asks."""


def state_label(node: Node) -> Optional[str]:
    """The lifecycle state of ``node`` ("unconfigured", "inactive", "active", …); None if it is
    not a lifecycle node."""
    if not isinstance(node, LifecycleNode):
        return None
    return node._state_machine.current_state[1]


def is_active(node: Node) -> bool:
    return not isinstance(node, LifecycleNode) or node._state_machine.current_state[0] == State.PRIMARY_STATE_ACTIVE


def autostart(node: Node, described: str) -> None:
    """Configure, then activate ``node`` (a lifecycle node), from whatever state its constructor
    left it in; ``described``: how errors name it."""
    if not isinstance(node, LifecycleNode):
        raise LifecycleError(f"{described} has lifecycle: {AUTOSTART}, but {type(node).__name__} is not a "
                             f"rclpy.lifecycle.LifecycleNode")
    for name, trigger, before in (("configure", node.trigger_configure, State.PRIMARY_STATE_UNCONFIGURED),
                                  ("activate", node.trigger_activate, State.PRIMARY_STATE_INACTIVE)):
        if node._state_machine.current_state[0] == before:
            outcome = trigger()
            if outcome != TransitionCallbackReturn.SUCCESS:
                raise LifecycleError(f"{described}: its {name} transition returned {outcome.to_label()} "
                                     f"(now {state_label(node)})")
    if not is_active(node):
        raise LifecycleError(f"{described}: not active after autostart (now {state_label(node)})")
