"""What the host does with each entity of a hosted node, whenever the node made it.

A node may create publishers, subscriptions, timers, services, clients and action endpoints in
its constructor, in a lifecycle transition (``on_configure``) or in any callback. With the
lockstep executor each is hosted the same way, whenever it appears (the executor reports a node
whose entities changed before its next walk; hosting/executors/lockstep.py); rclpy's stock
executors, kept for comparison, get what the nodes have when they are adopted:

- its callbacks are guarded: a failure is the robot's (hosting/callback_guard.py);
- its services are served in process, its clients call in process or through the call relay,
  its action endpoints are polled by the walk (hosting/services.py);
- a publisher on the robot's ``cmd_vel`` is told to the simulator as the robot's controller (its
  answers count); each was checked against the topic contract when made (hosting/building.py);
- the node gets its parameter services, in process (hosting/parameters.py).
"""
from __future__ import annotations

from typing import Optional

from rclpy.node import Node

from composed_sim.hosting import ContractViolation
from composed_sim.hosting.callback_guard import CallbackGuard
from composed_sim.hosting.parameters import HostedParameterServices
from composed_sim.hosting.services import ServiceDirectory
from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import cmd_vel_gids
from composed_sim.ros.simulator_node import AnswerTypeError


class HostedEntities:
    """The entities of one executor's nodes (a block of robots', or the run-wide nodes'); ``relay``:
    their process's run-wide relay (hosting/run_wide/relay.py), whose subscriptions of theirs the
    guard guards too."""

    def __init__(self, directory: ServiceDirectory, relay=None, guard: Optional[CallbackGuard] = None):
        self.directory = directory
        self._relay, self._guard = relay, guard
        self._node_info: dict[int, tuple[Optional[str], int, object]] = {}   # id(node) → robot, place, simulator
        self._publishers: dict[int, set[int]] = {}                          # id(node) → ids of its publishers seen
        if hasattr(directory.executor, "on_entities_changed"):      # the lockstep executor tells
            directory.executor.on_entities_changed = self.host_new

    def adopt(self, node: Node, robot: Optional[str], place: int, simulator=None) -> None:
        """``node`` is built: host what it has (``robot``: its robot, None for a run-wide node;
        ``place``: the robot's index in the run, or RUN_WIDE_ORIGIN; ``simulator``: the simulator
        node that serves the robot)."""
        self._node_info[id(node)] = (robot, place, simulator)
        self._publishers[id(node)] = {id(p) for p in node.publishers}
        if self._guard is not None and robot is not None:
            self._guard.guard(node, robot, simulator, self._relayed(node))
        self._host(node, place)
        HostedParameterServices(node, self.directory)      # kept by its services

    def host_new(self, node: Node) -> None:
        """``node`` created or destroyed entities since it was last looked at."""
        info = self._node_info.get(id(node))
        if info is None:
            return
        robot, place, simulator = info
        if self._guard is not None and robot is not None:
            self._guard.guard_new(node, self._relayed(node))
        self._host(node, place)
        if robot is not None:
            self._note_answers(node, robot, simulator)

    def _relayed(self, node: Node) -> list:
        return self._relay.subscriptions_of(node) if self._relay is not None else []

    def _host(self, node: Node, place: int) -> None:
        directory = self.directory
        for service in node.services:
            directory.host_service(node, service)
        for client in node.clients:
            directory.host_client(node, client, place)
        for waitable in node.waitables:
            if directory.is_action(waitable):
                directory.host_action(node, waitable)

    def _note_answers(self, node: Node, robot: str, simulator) -> None:
        """A new publisher on the robot's cmd_vel: the simulator takes its answers."""
        seen = self._publishers[id(node)]
        new = [p for p in node.publishers if id(p) not in seen]
        seen.update(id(p) for p in new)
        answers = [p for p in new if p.topic_name == c.topic_name(robot, c.CMD_VEL)]
        if simulator is None or not answers:
            return
        try:
            simulator.take_answers_as(robot, c.type_name(answers[0].msg_type))
        except AnswerTypeError as e:
            self._failed(node, ContractViolation(str(e)))
            return
        nodes = [n for n in self.directory.executor.get_nodes() if self._node_info.get(id(n), (None,))[0] == robot]
        simulator.note_controller(robot, [gid for n in nodes for gid in cmd_vel_gids(n, robot)])

    def _failed(self, node: Node, error: Exception) -> None:
        """The node's fault: its robot fails (a controller process of its own ends with it)."""
        if self._guard is None:
            raise error
        self._guard.node_failed(node, error)
