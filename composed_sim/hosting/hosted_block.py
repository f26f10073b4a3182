"""One way to host a block of nodes: every place that hosts nodes uses it (a participant group's
robots, a robot in a controller process of its own, the run-wide nodes).

A block is the nodes of one executor. Whatever a node makes, in its constructor, a lifecycle
transition (``on_configure``) or any callback, is hosted the same way whenever it appears (the
lockstep executor reports a node whose entities changed before its next walk; rclpy's stock
executors, kept for comparison, get what the nodes have when they are adopted):

- its callbacks are guarded: a failure is the robot's (hosting/guard/callback_guard.py);
- its services are served in process, its clients call in process, through the call relay (to
  another place of the run) or through DDS, its action endpoints are polled by the walk
  (hosting/calls/directory.py);
- a publisher on the robot's ``cmd_vel`` is told to the simulator as the robot's controller (its
  answers count); each was checked against the topic contract when made (hosting/building/nodes.py);
- the node gets its parameter services, in process (hosting/calls/parameters.py);
- requests that other processes send to its services are taken as each tick starts
  (hosting/calls/outside.py).

The simulator's own services of the block (each drone's Crazyswarm2 services, hosting/drones.py)
are served the same way (``serve``).
"""
from __future__ import annotations

import collections
import functools
from typing import Callable, Collection, Iterable, Optional

from rclpy.node import Node

from composed_sim.hosting import ContractViolation
from composed_sim.hosting.guard.callback_guard import CallbackGuard
from composed_sim.hosting.calls.outside import OutsideCalls
from composed_sim.hosting.calls.parameters import HostedParameterServices
from composed_sim.hosting.calls.between_places import service_type_name
from composed_sim.hosting.calls.directory import ServiceDirectory
from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import cmd_vel_gids
from composed_sim.ros.simulator_node import AnswerTypeError


class HostedBlock:
    """The nodes of one executor, hosted. ``calls``: the process's call relay
    (hosting/calls/between_places.py), through which calls to the other places of the run go, and which
    hands this block the calls to ``places``; None: such calls go through DDS. ``relay``:
    the process's run-wide relay (hosting/run_wide/relay.py), whose subscriptions of a node's the
    guard guards too. ``guard``: what makes a faulty callback its robot's fault (None: a failure
    ends the process, a controller process of its own)."""

    def __init__(self, executor, nodes: Iterable[tuple[Node, Optional[str], int, object]] = (), *,
                 robots: Collection[str], graph_changed: Optional[Callable[[], bool]] = None,
                 calls=None, places: Collection[int] = (), relay=None, guard: Optional[CallbackGuard] = None,
                 on_new_endpoints: Optional[Callable[[str, list, list], None]] = None):
        """``nodes``: each built node, with its robot, place and simulator node (``adopt``).
        ``robots``: the run's, whose nodes are all the run's own: requests from other processes
        to the block's services are taken at each tick's start (``start_tick``); whether the ROS
        graph changed comes from ``graph_changed``, the host's own watch where it has one (a second
        watch of one participant would take its triggers), else from a watch of the first node's
        participant. ``on_new_endpoints``: told of the publishers and subscriptions a robot's node
        makes after it was adopted (a lifecycle node's, in a transition): where the simulator is in
        another process, it must hear of a new cmd_vel publisher, or of a new reader of the robot's
        sensors."""
        self.executor = executor
        self.directory = ServiceDirectory(executor, relay=calls)
        self._calls = calls
        if calls is not None:
            calls.serve(places, self.directory)
        self._relay, self._guard = relay, guard
        self._node_info: dict[int, tuple[Optional[str], int, object]] = {}   # id(node) → robot, place, simulator
        self._seen: dict[int, set[int]] = {}              # id(node) → ids of its publishers and subscriptions seen
        self.on_new_endpoints = on_new_endpoints
        # Nodes that made entities since the last look: the lockstep executor tells before its
        # next walk; under rclpy's stock executors a node's own wake-up call notes it (a
        # callback on one of their threads may make it), hosted as the next tick starts.
        self._changed: collections.deque = collections.deque()
        self._stock = not hasattr(executor, "on_entities_changed")
        if not self._stock:
            executor.on_entities_changed = self.host_new
        nodes = list(nodes)
        for node, robot, place, simulator in nodes:
            self.adopt(node, robot, place, simulator)
        self._outside: Optional[OutsideCalls] = None
        if graph_changed is not None:
            self._outside = OutsideCalls(self.directory, robots, graph_changed)
        elif nodes:
            self._outside = OutsideCalls.watching(self.directory, robots, nodes[0][0])

    # --- nodes ----------------------------------------------------------------------------------

    def adopt(self, node: Node, robot: Optional[str], place: int, simulator=None) -> None:
        """``node`` is built: host what it has (``robot``: its robot, None for a run-wide node;
        ``place``: the robot's index in the run, or RUN_WIDE_ORIGIN; ``simulator``: the simulator
        node that serves the robot)."""
        self._node_info[id(node)] = (robot, place, simulator)
        self._seen[id(node)] = {id(e) for e in (*node.publishers, *node.subscriptions)}
        if self._guard is not None and robot is not None:
            self._guard.guard(node, robot, simulator, self._relayed(node))
        self._host(node, place)
        HostedParameterServices(node, self.directory)      # kept by its services
        self._announce(node, place)
        if self._stock:
            wake = node._wake_executor          # rclpy's Node calls it after making an entity

            def noting(node=node, wake=wake):
                self._changed.append(node)
                wake()
            node._wake_executor = noting

    def host_new(self, node: Node) -> None:
        """``node`` created or destroyed entities since it was last looked at."""
        info = self._node_info.get(id(node))
        if info is None:
            return
        robot, place, simulator = info
        if self._guard is not None and robot is not None:
            self._guard.guard_new(node, self._relayed(node))
        self._host(node, place)
        self._announce(node, place)
        if robot is not None:
            self._note_endpoints(node, robot, simulator)

    def serve(self, node: Node, services: list) -> None:
        """Services of the simulator's side, made by ``node`` (in the block's executor), each with
        ``name``, ``srv_type``, ``callback``, ``on_graph`` and ``robot`` (its place): served in
        process; on the ROS graph from the start where ``on_graph``, else once a client in another
        process looks for it (a DDS endpoint each costs the participant's set-up); on the run's
        graph of calls between places (a client elsewhere finds it ready)."""
        directory = self.directory
        for spec in services:
            if spec.on_graph:
                directory.host_service(node, node.create_service(spec.srv_type, spec.name, spec.callback))
            else:
                entry = directory.add_in_process(node, spec.name, spec.srv_type, spec.callback,
                                                 node.default_callback_group)
                entry.on_outside = functools.partial(self._expose, node, entry)
        if self._calls is not None:
            self._calls.announce([(spec.robot, spec.name, service_type_name(spec.srv_type)) for spec in services])

    def _expose(self, node: Node, entry) -> None:
        if entry.service is None:
            self.directory.attach_dds(entry, Node.create_service(node, entry.srv_type, entry.name, entry.callback,
                                                                 callback_group=entry.group))

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
                directory.host_action(node, waitable, place)

    def _announce(self, node: Node, place: int) -> None:
        """The node's services, on the run's graph of calls between places: a client of another
        place (another process, maybe) finds them ready, as its own process would on the ROS graph."""
        if self._calls is not None:
            self._calls.announce([(place, entry.name, service_type_name(entry.srv_type))
                                  for entry in self.directory.served_by(node)])

    def _note_endpoints(self, node: Node, robot: str, simulator) -> None:
        """New publishers and subscriptions of a robot's node; a new publisher on its cmd_vel: the
        simulator takes its answers."""
        seen = self._seen[id(node)]
        publishers = [p for p in node.publishers if id(p) not in seen]
        subscriptions = [s for s in node.subscriptions if id(s) not in seen]
        seen.update(id(e) for e in (*publishers, *subscriptions))
        if (publishers or subscriptions) and self.on_new_endpoints is not None:
            self.on_new_endpoints(robot, publishers, subscriptions)
        answers = [p for p in publishers if p.topic_name == c.topic_name(robot, c.CMD_VEL)]
        if simulator is None or not answers:
            return
        try:
            simulator.take_answers_as(robot, c.type_name(answers[0].msg_type))
        except AnswerTypeError as e:
            self._failed(node, ContractViolation(str(e)))
            return
        nodes = [n for n in self.executor.get_nodes() if self._node_info.get(id(n), (None,))[0] == robot]
        simulator.note_controller(robot, [gid for n in nodes for gid in cmd_vel_gids(n, robot)])

    def _failed(self, node: Node, error: Exception) -> None:
        """The node's fault: its robot fails (a controller process of its own ends with it)."""
        if self._guard is None:
            raise error
        self._guard.node_failed(node, error)

    # --- calls from other processes -------------------------------------------------------------

    def start_tick(self) -> None:
        """As a tick starts: what nodes made since (under a stock executor), hosted; the requests
        other processes sent, taken."""
        while self._changed:
            self.host_new(self._changed.popleft())
        if self._outside is not None:
            self._outside.take()

    def close(self) -> None:
        if self._outside is not None:
            self._outside.close()
            self._outside = None
