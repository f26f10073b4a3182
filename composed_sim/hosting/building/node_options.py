"""Building a hosted node from any rclpy Node class, as a component container builds a component.

A ROS 2 node is written for a process of its own: ``super().__init__('talker')``, with its
namespace, parameters and remappings from the command line (``--ros-args``) and its clock from
/clock. Hosted by the hundred in one process, it gets the same things from the host instead:
while its constructor runs, ``Node.__init__`` is handed the options a launch file would have
given its process (context, namespace, parameter overrides, ``--ros-args`` with the parameters
file and the remappings), whatever the class's own signature: ``__init__(self)``,
``__init__(self, **kwargs)``, or one that passes some options itself (its own namespace is
nested in the robot's; its own parameter overrides come before the host's).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Callable, Mapping, Optional, Sequence

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from composed_sim.ros.driven_clocks import follow_sim_time
from composed_sim.ros.robot_settings import quiet_node_options


@dataclass(frozen=True)
class HostedNodeOptions:
    """What the host gives one node: the options its own process would have had."""
    context: Context
    namespace: str                                   # the robot's ("/bot3"), or "/" for a run-wide node
    parameters: Sequence[Parameter] = ()             # over those of the parameters file
    params_file: Optional[str] = None                # a ROS 2 parameters file (rcl reads it)
    remappings: Mapping[str, str] = field(default_factory=dict)
    # The node's logger instead of rclpy's (hosting/guard/node_logs.py), installed as soon as
    # Node.__init__ returns, so that the rest of the constructor logs through it too.
    logger: Optional[Callable[[Node], object]] = None

    def cli_args(self) -> list[str]:
        """The node's own ``--ros-args``, as ``ros2 run … --ros-args`` would pass them."""
        args = ["--ros-args"]
        if self.params_file is not None:
            args += ["--params-file", self.params_file]
        for source, target in self.remappings.items():
            args += ["-r", f"{source}:={target}"]
        return args if len(args) > 1 else []

    def node_kwargs(self, given: Mapping) -> dict:
        """``Node.__init__``'s keyword arguments: the host's, merged with what the class passed."""
        own_namespace = (given.get("namespace") or "").strip("/")
        namespace = "/" + "/".join(p for p in (self.namespace.strip("/"), own_namespace) if p)
        quiet = quiet_node_options([*(given.get("parameter_overrides") or ()), *self.parameters])
        return {**given, **quiet, "context": self.context, "namespace": namespace,
                "cli_args": [*(given.get("cli_args") or ()), *self.cli_args()],
                "use_global_arguments": False}


_constructing = threading.Lock()      # one node's construction at a time: Node.__init__ is swapped


def construct(cls: type[Node], options: HostedNodeOptions,
              prepare: Callable[[Node], None] = lambda node: None) -> Node:
    """``cls()``, its ``Node.__init__`` given ``options``; ``prepare(node)`` runs before the
    constructor (to put its timers on sim time, say: nodes create them there)."""
    node = cls.__new__(cls)
    prepare(node)
    plain = Node.__init__

    def hosted_init(self, node_name, *args, **kwargs):
        # The class calls super().__init__(…), which finds this function on Node whatever the
        # class's own signature. Only the node being built gets the host's options: a Node it
        # builds itself is built as it asks.
        nonlocal node
        ours = self is node
        if ours:
            kwargs, node = options.node_kwargs(kwargs), None
        plain(self, node_name, *args, **kwargs)
        if ours:
            # Its clock is on sim time from the start, as ``use_sim_time`` puts a process's node:
            # until the host sets the first tick's time it reads 0 (in a constructor, in an
            # autostart's transitions), never the wall clock.
            follow_sim_time(self.get_clock())
        if ours and options.logger is not None:
            self._logger = options.logger(self)      # what Node.get_logger() returns

    with _constructing:
        Node.__init__ = hosted_init
        try:
            built = node
            built.__init__()
        finally:
            Node.__init__ = plain
    return built
