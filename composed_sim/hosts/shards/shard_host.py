"""A controller shard: some robots' controller nodes in one process, serving a simulator that runs
elsewhere (``composed-sim host WORLD --robots 0-639``; the simulator runs with
``composed-sim run WORLD --external-controllers``).

It is the composed host without the simulator: one rclpy context, one executor, the very same
robot nodes (``create_robot_nodes``) on the very same topics. DDS carries the topics between
machines; nothing else crosses. Sim time: one ``/clock`` subscription per shard sets every hosted
node's clock (as the composed host does from the simulator node), instead of one per node.

Life cycle: build the nodes → wait until every hosted controller's contract endpoints are matched
with a simulator's → announce the shard (``announce.py``) → serve ticks until the simulator's
``/clock`` publisher is gone (the run ended, failed or was killed: DDS reports the writer's removal
at once on a clean exit, after the participant lease on a crash) or a stop is requested
(SIGINT/SIGTERM in the CLI).
"""
from __future__ import annotations

import os
import re
import socket
import time
from typing import Callable, Optional

import rclpy
from rclpy.clock import Clock as RosClock
from rclpy.context import Context
from rclpy.node import Node
from rclpy.time import Time as RosTime

from composed_sim.hosting import (before_each_tick, check_executor, contract_endpoints, create_robot_nodes,
                                  DEFAULT_EXECUTOR, driven_by_caller, HostedBlock, HostError, load_classes,
                                  make_executor, matched, poll_until, SetupWarnings, shut_down, Spinning)
from composed_sim.hosts.shards.robot_ranges import format_ranges
from composed_sim.hosts.shards.announce import ShardAnnouncer, ShardInfo, world_fingerprint
from composed_sim.ros import contract as c
from composed_sim.ros.answer_subscription import cmd_vel_gids
from composed_sim.ros.driven_clocks import follow_sim_time, set_sim_time
from composed_sim.world.schema import World

LIVENESS_PERIOD_S = 0.2      # how often a serving shard looks whether its simulator is still there


class ShardHost:
    """Context manager owning the shard's context, nodes and executor, destroyed in order."""

    def __init__(self, world: World, robots: list[int], *, executor: str = DEFAULT_EXECUTOR, domain_id: int = 0,
                 should_stop: Callable[[], bool] = lambda: False):
        check_executor(executor)
        if not robots:
            raise HostError("a shard needs at least one robot")
        self.world = world
        self.robots = list(robots)
        self.executor_kind = executor
        self.domain_id = domain_id
        self.should_stop = should_stop
        self.shard_id = f"{socket.gethostname()}:{os.getpid()}"
        self.context: Optional[Context] = None
        self.announcer: Optional[ShardAnnouncer] = None
        self.robot_nodes: list[list[Node]] = []      # per hosted robot: its nodes
        self.spinning: Optional[Spinning] = None
        self._clocks: list[RosClock] = []
        self._clock_sub = None
        self.block: Optional[HostedBlock] = None

    def __enter__(self) -> "ShardHost":
        try:
            names = self.world.robot_names()
            groups = self.world.group_of_robot()
            robot_names = frozenset(names)
            classes = load_classes(self.world)
            self.context = Context()
            rclpy.init(context=self.context, domain_id=self.domain_id)
            node_name = "composed_sim_shard_" + re.sub(r"\W", "_", self.shard_id)
            self.announcer = ShardAnnouncer(self.context, node_name)
            self._clock_sub = self.announcer.node.create_subscription(
                c.CLOCK_TYPE, c.CLOCK_TOPIC, self._on_clock, 10)
            self.spinning = Spinning(make_executor(self.executor_kind, self.context))
            # First: the lockstep executor's ordered walk then moves the clocks to a tick's time
            # before the controllers read that tick's sensors.
            self.spinning.executor.add_node(self.announcer.node)
            warnings = SetupWarnings()
            # Its robots' nodes hosted as in the composed host (hosting/hosted_block.py); calls to a
            # place outside the shard go through DDS; calls from other processes are taken as each
            # tick starts.
            self.block = HostedBlock(self.spinning.executor)
            self.block.watch_outside_calls(names, graph_of=self.announcer.node)
            for i in self.robots:
                if self.should_stop():
                    break
                group = groups[i]
                built = create_robot_nodes(self.world, group, names[i], self.context, classes=classes,
                                           robots=robot_names, clock_from_stamps=True, warnings=warnings)
                nodes = built.nodes
                sensors = {c.topic_name(names[i], t) for t in c.SENSOR_TOPICS}
                before_each_tick([s for n in nodes for s in n.subscriptions if s.topic_name in sensors],
                                 lambda stamp, timers=built.tick_timers: [t.advance_to(stamp) for t in timers])
                for node in nodes:
                    clock = node.get_clock()
                    follow_sim_time(clock)
                    self._clocks.append(clock)
                    self.spinning.executor.add_node(node)
                    self.block.adopt(node, names[i], i)
                self.robot_nodes.append(nodes)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _on_clock(self, msg) -> None:
        set_sim_time(self._clocks, RosTime.from_msg(msg.clock).nanoseconds)
        if self.block is not None:
            self.block.take_outside_calls()

    # --- start-up: match, then announce -----------------------------------------------------

    def wait_for_simulator(self, timeout_s: float) -> bool:
        """Until every hosted controller's contract endpoints (and our /clock subscription) are
        matched with a simulator's; then announce. False if a stop was requested first. Without
        this a tick-0 sensor or answer could go to a not yet matched endpoint and be lost."""
        names = self.world.robot_names()
        endpoints = [(i, e) for i, nodes in zip(self.robots, self.robot_nodes)
                     for e in contract_endpoints(nodes, names[i])]
        unmatched = lambda: sorted({i for i, e in endpoints if not matched(e)})     # noqa: E731 - re-read at each look, one expression
        found = poll_until(lambda: not unmatched() and self._clock_sub.get_publisher_count() >= 1, timeout_s,
                           self.should_stop)
        if found is None:
            missing = unmatched()
            what = (f"the controllers of robots {format_ranges(missing)} found no matching simulator "
                    f"endpoints" if missing else "no simulator /clock publisher was found")
            raise HostError(f"shard {format_ranges(self.robots)}: {what} within {timeout_s:g} s in ROS "
                            f"domain {self.domain_id}; start `composed-sim run WORLD --external-controllers` "
                            f"with the same world and domain, and check the discovery settings "
                            f"(docs/distributed.md)")
        if not found:
            return False
        topics = {}
        for i, e in endpoints:
            if e.topic_name != c.CLOCK_TOPIC:
                topics.setdefault(i, set()).add(e.topic_name.rsplit("/", 1)[1])
        gids = {i: [gid for node in nodes for gid in cmd_vel_gids(node, names[i])]
                for i, nodes in zip(self.robots, self.robot_nodes)}
        self.announcer.announce(ShardInfo(self.shard_id, self.robots, world_fingerprint(self.world),
                                          {i: sorted(t) for i, t in topics.items()}, gids))
        return True

    # --- serving ----------------------------------------------------------------------------

    def serve(self) -> str:
        """Run the controllers until the simulator is gone ("simulator gone") or a stop is
        requested ("stopped")."""
        spinning = self.spinning
        if not driven_by_caller(self.executor_kind, guarded=False):
            spinning.start_thread()
        next_check = time.monotonic() + LIVENESS_PERIOD_S
        while True:
            if self.should_stop():
                return "stopped"
            if time.monotonic() >= next_check:
                if self._clock_sub.get_publisher_count() == 0:
                    return "simulator gone"
                next_check = time.monotonic() + LIVENESS_PERIOD_S
            if spinning.thread is None:
                spinning.executor.spin_once(timeout_sec=LIVENESS_PERIOD_S / 4)
            else:
                time.sleep(LIVENESS_PERIOD_S / 4)

    def __exit__(self, *exc) -> None:
        if self.block is not None:
            self.block.close()
            self.block = None
        shut_down(self.spinning, [*(n for nodes in self.robot_nodes for n in nodes),
                                  *([self.announcer] if self.announcer is not None else [])], self.context)
        self.robot_nodes, self.announcer, self.context = [], None, None
