"""The ROS side of a block of robots, in this process: their participant groups and one executor.

A participant group is one rclpy Context (one DDS participant) holding a SimulatorNode for up to
``robots_per_participant`` robots and those robots' controller nodes. A group's topics are its
robots' own, so it is self-contained, and the participants of one process ignore one another
(hosting/dds/participants.py): Fast DDS's endpoint matching, quadratic in a participant's endpoints,
then costs O(E²/K) instead of O(E²). Processes outside still discover every group.

The single-process composed host holds every robot's groups; each worker process of the worker
host holds its block's (hosts/workers/worker_host.py). Either way, every per-robot message stays inside a
participant (with the lockstep executor, a robot's sensors and answers are handed over in process
while nothing else listens: ros/in_process.py), and the robots are numbered from the start
of the block: the SensorFrame handed to ``exchange.publish_tick`` covers the block only.
"""
from __future__ import annotations

import sys
import time
from typing import Callable, Optional

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import Executor
from rclpy.node import Node

from composed_sim.world.robot_models import get_model
from composed_sim.hosting.guard import callback_guard
from composed_sim.hosting.guard.callback_guard import CallbackGuard, refuse_shutdown_from_callbacks
from composed_sim.hosting.process_hosting import ROBOTS_PER_PARTICIPANT, ProcessHosting
from composed_sim.hosting import HostError
from composed_sim.hosting.building.nodes import SetupWarnings, create_robot_nodes, load_classes
from composed_sim.hosting.run_wide_nodes import create_run_wide_nodes
from composed_sim.hosting.building.wiring import answer_type
from composed_sim.hosting.drones import ProcessDrones, flying_robots, has_run_wide_nodes
from composed_sim.hosting.hosted_block import HostedBlock
from composed_sim.hosting.executors.tick_serving import TickServing
from composed_sim.hosting.executors.running import (SETTLE_ROUNDS, Spinning, check_executor, make_executor,
                                                   refuse_coroutines_for_events)
from composed_sim.hosting.guard.node_logs import NodeLogs
from composed_sim.hosting.guard.node_time import NodeTime
from composed_sim.hosting.nodes_exchange import NodesExchange
from composed_sim.hosting.run_wide_nodes import RunWideNodes, first_timer_tick_of, wait_for_run_wide_timers
from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import cmd_vel_gids, publisher_gid
from composed_sim.ros import in_process
from composed_sim.ros.in_process import GraphWatch, Link, inbox_of, link_answers, link_subscriptions
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.dds.participants import ignore_participants_of_this_process
from composed_sim.ros.rcl_graph import GraphChanges
from composed_sim.ros.robot_settings import robot_settings
from composed_sim.hosting.calls.between_places import CallRelay
from composed_sim.hosting.run_wide.relay import Message, RunWideRelay
from composed_sim.ros.simulator_node import AnswerTypeError, SimulatorNode
from composed_sim.world.schema import World

DISCOVERY_TIMEOUT_S = 60.0


def simulator_node_name(group: int) -> str:
    """The run's participant groups are numbered over all its processes: names stay unique."""
    return "composed_sim" if group == 0 else f"composed_sim_{group}"


class ParticipantGroups(TickServing):
    """Robots ``start … stop-1`` of ``world``: contexts, simulator nodes, controllers, executor.

    A context manager; ``__exit__`` destroys the nodes before their contexts."""

    def __init__(self, world: World, start: int, stop: int, hosting: ProcessHosting, *,
                 robots_per_participant: int = ROBOTS_PER_PARTICIPANT, first_group: int = 0,
                 logs: Optional[NodeLogs] = None):
        """``hosting``: its executor and domain. ``first_group``: the number of this block's first
        participant group in the run (the block of robot 0 has group 0, which publishes /clock).
        ``logs``: where the nodes' log lines and the tracebacks of their failing callbacks go
        (hosting/guard/node_logs.py)."""
        check_executor(hosting.executor)
        if robots_per_participant < 1:
            raise HostError(f"robots per participant must be at least 1, got {robots_per_participant}")
        self.world = world
        self.start, self.stop = start, stop
        self.hosting = hosting
        self.robots_per_participant = robots_per_participant
        self.first_group = first_group
        self.logs = logs
        self.contexts: list[Context] = []
        self.simulator_nodes: list[SimulatorNode] = []      # one per group, in robot order
        self.robot_nodes: list[list[Node]] = []             # per robot of the block: its nodes
        self.controllers: list[Node] = []                   # every robot node, robot by robot
        self.relay = RunWideRelay(world.robot_names())
        self._robot_set = frozenset(world.robot_names())
        # Service calls between places (robots, run-wide).
        self.calls = CallRelay(world.robot_names(), relays_actions=hosting.lockstep)
        self.block: Optional[HostedBlock] = None            # how their nodes are hosted
        # Robots whose nodes publish no cmd_vel yet (building/wiring.answer_rule): they keep their
        # last command until their first answer.
        self.answers_later: list[str] = []
        self._first_timer_ticks: dict[str, int] = {}      # robots answering from timers: when they first may
        # Where a round of calls between places goes when this block is one of several processes
        # (a worker: hosting/calls/rounds.py): given the calls made here, the calls for here, or
        # None once the run is quiet everywhere. None: every place is in this process.
        self.remote: Optional[Callable[[list], Optional[list]]] = None
        self._rounds_over = False
        self.run_wide: Optional[RunWideNodes] = None        # the world's run-wide nodes (block of robot 0)
        self._tick_timers = []                              # SimTimers the host moves to each tick's time
        self._settle = False
        self._quiet_robots = False                          # any robot that answers when published?
        self._calls_at_open: dict[str, int] = {}            # guard.calls_of when the tick opened
        self.exchange: Optional[NodesExchange] = None
        self.links: list[Link] = []                         # in-process paths (ros/in_process.py)
        self._graph_watches: list[GraphWatch] = []          # per group: when to ask for matched counts
        self._outside_watches: list = []                    # per group: has its graph changed since?
        self._run_wide_graph: Optional[Callable[[], bool]] = None  # has the run-wide nodes' graph changed?
        self.graph_changes: Optional[GraphChanges] = None   # what tells them the graph changed
        self.executor: Optional[Executor] = None
        self.spinning: Optional[Spinning] = None
        self.guard: Optional[CallbackGuard] = None
        self.node_time = NodeTime()                         # CPU seconds in the nodes' own code
        self.drones = ProcessDrones(world)                  # the drones' Crazyswarm2 endpoints (hosting/drones.py)

    def __enter__(self) -> "ParticipantGroups":
        try:
            self._build()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _build(self) -> None:
        world = self.world
        classes = load_classes(world)
        ignore_participants_of_this_process()
        lockstep = world.lockstep
        self.guard = CallbackGuard(lockstep.watchdog_s, lockstep.unresponsive_s, self.node_time)
        logs = self.logs
        if logs is not None:
            self.guard.on_exception = lambda robot, node, error: logs.exception(
                robot, type(node), node.get_logger().name, error, skip=callback_guard.__file__)
        warnings = SetupWarnings()
        first_robots = []                    # per group: the index of its first robot in robot_nodes
        for k, first in enumerate(range(self.start, self.stop, self.robots_per_participant)):
            first_robots.append(len(self.robot_nodes))
            self._build_group(self.first_group + k, range(first, min(self.stop, first + self.robots_per_participant)),
                              classes, warnings)
        self.exchange = NodesExchange(self.simulator_nodes, node_time=self.node_time)
        self.note_run_wide_timers(self.run_wide_timers)
        self.executor = make_executor(self.hosting.executor, self.contexts[0], robots=self.stop - self.start)
        if isinstance(self.executor, LockstepExecutor):
            self.executor.watcher = self.guard
        self.spinning = Spinning(self.executor)
        # Simulator nodes last, so that the lockstep executor's one ordered pass runs every
        # controller on its sensors first and then collects the answers they just published.
        for node in (*self.controllers, *self.simulator_nodes, *self.drones.nodes):
            self.executor.add_node(node)
        self._host_entities()
        # A tick's answers may leave work behind (a later node of a chain, a run-wide message
        # published after the answer): run it before the tick closes, so that what the tick
        # sends on does not depend on the walk in which the last robot answered.
        names = world.robot_names()
        sensor_topics = {c.topic_name(r, t) for r in names[self.start:self.stop] for t in c.SENSOR_TOPICS}
        # A drone's nodes are never waited for (its firmware answers): what they do runs within the tick.
        flying = flying_robots(world)
        self._settle = self.relay.in_use or any(s.topic_name not in sensor_topics
                                                for node in self.controllers for s in node.subscriptions) \
            or any(flying[i] and nodes for i, nodes in zip(range(self.start, self.stop), self.robot_nodes))
        self._wait_for_discovery()
        gids = {names[i]: [gid for node in nodes for gid in cmd_vel_gids(node, names[i])]
                for i, nodes in zip(range(self.start, self.stop), self.robot_nodes)}
        for sim_node in self.simulator_nodes:
            sim_node.note_controllers(gids)
        self._link_in_process(first_robots)
        self.drones.refresh()          # the setpoint topics the robots' own nodes publish

    def _build_group(self, group: int, block: range, classes: dict, warnings: SetupWarnings) -> None:
        """Participant group ``group``: a context of its own, the robots ``block``'s nodes, their
        simulator node (and, in group 0, the run-wide nodes)."""
        world, logs = self.world, self.logs
        names, groups = world.robot_names(), world.group_of_robot()
        context = Context()
        rclpy.init(context=context, domain_id=self.hosting.domain_id)
        refuse_shutdown_from_callbacks(context, self.guard)
        self.contexts.append(context)
        if group == 0 and has_run_wide_nodes(world):    # first: they are delivered to before the robots
            self.run_wide = create_run_wide_nodes(world, context, classes=classes, relay=self.relay, logs=logs)
        # The nodes first: the simulator node subscribes to each robot's cmd_vel with the
        # type its nodes publish (one participant allows one type per topic).
        first_robot = len(self.robot_nodes)
        for i in block:
            built = create_robot_nodes(world, groups[i], names[i], context, classes=classes, relay=self.relay,
                                       origin=i, robots=self._robot_set, logs=logs, warnings=warnings)
            self.robot_nodes.append(built.nodes)
            self.controllers += built.nodes
            self._tick_timers += built.tick_timers
            if built.answers_later:
                self.answers_later.append(names[i])
            elif built.first_timer_tick:
                self._first_timer_ticks[names[i]] = built.first_timer_tick
        block_nodes = self.robot_nodes[first_robot:]
        sim_node = SimulatorNode([names[i] for i in block], [get_model(world.robots[groups[i]].model) for i in block],
                                 context=context, tick_ns=world.tick_ns,
                                 rows=np.arange(block.start - self.start, block.stop - self.start),
                                 node_name=simulator_node_name(group), lockstep=world.lockstep,
                                 rab_payload_bytes=world.range_and_bearing.payload_bytes,
                                 publish_clock=group == 0,
                                 **{**robot_settings(world, block),
                                    "answer_types": [answer_type(nodes, names[i], world.robots[groups[i]].cmd_vel)
                                                     for i, nodes in zip(block, block_nodes)]})
        sim_node.on_failed.append(self.guard.stop_worker)
        sim_node.drones = self.drones.make_endpoints(context, block, simulator_node_name(group), self.start)
        later = set(self.answers_later)
        sim_node.answer_later([names[i] for i in block if names[i] in later])
        for i in block:
            if names[i] in self._first_timer_ticks:
                sim_node.answer_later([names[i]], until_tick=self._first_timer_ticks[names[i]])
        self.simulator_nodes.append(sim_node)
        for nodes in block_nodes:
            for node in nodes:
                sim_node.clocks.drive(node)

    def note_run_wide_timers(self, tick: int) -> None:
        """Until tick ``tick`` the robots may wait for the run-wide nodes' first timer (they may be
        another process's): run_wide_nodes.wait_for_run_wide_timers."""
        wait_for_run_wide_timers(self.simulator_nodes, tick)
        self._quiet_robots = any(node.when_published.any() for node in self.simulator_nodes)

    def _host_entities(self) -> None:
        """Every node hosted (hosting/hosted_block.py): guarded callbacks, services and calls in
        process or through the call relay, parameter services, calls from other processes."""
        if self.hosting.executor == "events":
            refuse_coroutines_for_events(self.controllers)
        if self.hosting.executor == "multi-threaded" and any(n.clients for n in self.controllers):
            print("composed-sim: warning: under rclpy's multi-threaded executor the ticks in which calls and "
                  "feedback complete follow its threads' timing (a blocking call holds one of them until answered; "
                  "in worker processes a call to a run-wide node made after the tick's rounds completes as the "
                  "next tick opens). The default executor runs them within the tick, in one order", file=sys.stderr)
        names = self.world.robot_names()
        places = iter(range(self.start, self.stop))
        self.block = HostedBlock(self.executor, [(node, robot, i, sim_node) for sim_node in self.simulator_nodes
                                                 for robot, i in zip(sim_node.robots, places)
                                                 for node in self.robot_nodes[i - self.start]],
                                 robots=names, graph_changed=lambda: any([changed() for changed in self._outside_watches]),
                                 calls=self.calls, places=range(self.start, self.stop), relay=self.relay, guard=self.guard)
        if self.run_wide is not None:
            self.run_wide.host(self.relay, self.calls, names,
                               lambda: self._run_wide_graph is not None and self._run_wide_graph())
        self.drones.host(self.block)
        self.drones.attach_server(self.run_wide)

    def _link_in_process(self, first_robots: list[int]) -> None:
        """With the lockstep executor, which takes from inboxes: each group's sensor messages go
        straight to its robots' nodes while nothing else listens (ros/in_process.py)."""
        if not (isinstance(self.executor, LockstepExecutor) and in_process.enabled()):
            return
        watched = []            # per group: (what asks DDS while the graph may change, its inboxes)
        for sim_node, first, end in zip(self.simulator_nodes, first_robots, [*first_robots[1:], len(self.robot_nodes)]):
            subscriptions = [s for nodes in self.robot_nodes[first:end] for node in nodes for s in node.subscriptions]
            links = link_subscriptions(sim_node.sensor_publishers(), subscriptions)
            read_raw = {link.topic for link in links if link.reaches_raw}
            for publisher in sim_node.device_publishers():    # readings beside the bytes (devices/common/handoff.py)
                publisher.hands_readings = any(p is not None and p.topic_name in read_raw for p in publisher.pubs)
            inboxes = [inbox_of(s) for s in subscriptions if inbox_of(s) is not None]
            for robot, nodes in zip(sim_node.robots, self.robot_nodes[first:end]):
                answers = sim_node.answer_subscription(robot)
                if answers is not None:
                    cmd_vel = c.topic_name(robot, c.CMD_VEL)
                    linked = link_answers([p for node in nodes for p in node.publishers if p.topic_name == cmd_vel],
                                          answers, publisher_gid)
                    links += linked
                    inboxes += [answers.inbox] if linked else []
            # The LEDs and rab_tx, which the simulator drains: by publication time, as from DDS.
            drained = sim_node.inbox_subscriptions()
            links += link_subscriptions([p for nodes in self.robot_nodes[first:end] for node in nodes
                                         for p in node.publishers], drained, timed=True)
            inboxes += [inbox_of(s) for s in drained if inbox_of(s) is not None]
            self.links += links
            # The device publishers ask DDS for readers of a topic nobody reads yet only while the
            # graph may change, as the links ask for their matched counts.
            watched.append(([*links, *sim_node.device_publishers()], inboxes))
        self.graph_changes = GraphChanges(self.simulator_nodes)
        self._graph_watches = [GraphWatch(self.graph_changes.poll(k), links, inboxes)
                               for k, (links, inboxes) in enumerate(watched)]
        # The services' clients in other processes, looked for again when a graph changed.
        self._outside_watches = [self.graph_changes.poll(k) for k in range(len(self.simulator_nodes))]
        if self.run_wide is not None:       # theirs is the first group's participant
            self._run_wide_graph = self.graph_changes.poll(0)
        self.drones.watch([self.graph_changes.poll(k) for k, node in enumerate(self.simulator_nodes)
                           if node.drones is not None])
        self.executor.wake()     # its walk picks the inboxes up

    # --- run-wide topics, at the tick's edges (hosting/run_wide/relay.py) --------------------------------

    def open_tick(self, tick: int, batch: list[Message]) -> None:
        """Before tick ``tick``'s sensors: the nodes' timers that do not wait for sensors move to
        the tick's time, and the run-wide messages of the batch reach their subscribers."""
        now_ns = tick * self.world.tick_ns
        now = time.monotonic()
        for watch in self._graph_watches:
            watch.start_tick(now)
        self.drones.refresh()
        if self._quiet_robots or self.remote is not None:
            self._calls_at_open = dict(self.guard.calls_of)
        if self.logs is not None:
            self.logs.tick = tick
        for timers in self._tick_timers:
            timers.advance_to(now_ns)
        for node in self.simulator_nodes:
            node.clocks.move_to(tick)
        lockstep = isinstance(self.executor, LockstepExecutor)
        if batch:
            self.relay.deliver(batch, run=self.executor.run_callback if lockstep else None)
            if self.first_group == 0:       # the run's first participant shows them to the world
                self.simulator_nodes[0].mirror_run_wide(batch, now_ns)
        # What reached the robots at the tick's start is handled before its sensors: the run-wide
        # messages, the calls of the run-wide nodes' part of the tick, requests from other processes.
        self.block.start_tick()
        self._rounds_over = False
        for _ in range(SETTLE_ROUNDS):      # rounds: a manager's configure, then activate, say
            if lockstep:
                self.executor.serve_handed_over()
            if not self._hand_over():
                break
        self._rounds_over = False           # the tick's own rounds come after its sensors

    @property
    def calls_leave(self) -> bool:
        """May this block's nodes call another place of the run, or be called from one (a run-wide
        node here, a client of another place's service)? Then processes hand calls over in rounds."""
        return self.run_wide is not None or self.calls.clients_leave

    def _hand_over(self) -> bool:
        """One round of the calls between places (hosting/calls/between_places.py), once this block is
        idle: the calls made since the last round go to their places (requests queued at their
        services, responses to their clients); the run-wide nodes then run until idle. False once
        no call is in flight anywhere: this phase of the tick is over."""
        if self.remote is None:
            if not self.calls.in_flight:
                return False
            incoming = self.calls.take_outbox()
        elif self._rounds_over:
            return False
        else:
            incoming = self.remote(self.calls.take_outbox())
            if incoming is None:
                self._rounds_over = True
                return False
        self.calls.deliver(incoming)
        if self.run_wide is not None:
            self.run_wide.run_until_idle()
        return True

    def take_drone_commands(self) -> list:
        """At the tick's close, before the run-wide nodes' part of the next: what the drones'
        endpoints and the crazyflie_server took in the tick (hosting/drones.py)."""
        return self.drones.take()

    def close_run_wide(self, next_tick: int) -> list[Message]:
        """After a tick's answers: the run-wide nodes' part of ``next_tick`` (their timers due by
        then, and what they have to handle), then what this process published on run-wide topics."""
        if self.run_wide is not None:
            if self.logs is not None:
                self.logs.tick = next_tick
            self.run_wide.start_tick(next_tick)
        return self.relay.take_outbox()

    @property
    def run_wide_timers(self) -> int:
        """The tick of the first timer of the run-wide nodes here (0: none, or none here)."""
        return first_timer_tick_of(self.run_wide)

    @property
    def nodes(self) -> int:
        return len(self.controllers) + len(self.simulator_nodes) + (len(self.run_wide.nodes) if self.run_wide else 0)

    def _wait_for_discovery(self) -> None:
        """Every robot's answer topic has a publisher and its sensors a subscriber before tick 0."""
        deadline = time.monotonic() + DISCOVERY_TIMEOUT_S
        while missing := self._unmatched():
            if time.monotonic() > deadline:
                seen = "; ".join(node.connection_of(r) for node in self.simulator_nodes
                                 for r in node.robots if r in missing[:3])
                raise HostError(f"the controllers of {', '.join(missing[:5])}{' …' if len(missing) > 5 else ''} "
                                f"were not connected within {DISCOVERY_TIMEOUT_S:.0f} s: each must publish "
                                f"{c.CMD_VEL.name} and subscribe to at least one sensor topic (seen: {seen})")
            time.sleep(0.01)

    def _unmatched(self) -> list[str]:
        later = set(self.answers_later)
        try:
            return [r for node in self.simulator_nodes for r in node.unmatched_robots() if r not in later]
        except AnswerTypeError as e:
            raise HostError(str(e)) from None

    def __exit__(self, *exc) -> None:
        if self.graph_changes is not None:
            self.graph_changes.close()
        if self.spinning is not None:
            self.spinning.stop()
        if self.block is not None:
            self.block.close()
        if self.run_wide is not None:
            self.run_wide.destroy()
        self.drones.destroy()
        for node in (*self.controllers, *self.simulator_nodes):
            node.destroy_node()
        self.controllers, self.simulator_nodes, self.robot_nodes, self.run_wide = [], [], [], None
        for context in self.contexts:
            if context.ok():
                Context.shutdown(context)       # the class's: the instance refuses it from callbacks
        self.contexts = []
