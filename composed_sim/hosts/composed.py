"""The composed host: the simulator and every controller node in one process, one domain, one
executor.

The robots are split into shards of ``robots_per_participant``: each shard is one rclpy Context
(one DDS participant) holding a SimulatorNode for its robots and their controller nodes. A shard's
topics are its robots' own, so it is self-contained, and the participants of this process ignore
one another (ros/participants.py): Fast DDS's endpoint matching, quadratic in a participant's
endpoints, then costs O(E²/K) instead of O(E²). Processes outside still discover every shard.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import Executor
from rclpy.node import Node

from composed_sim import plugins
from composed_sim.core.simulation import Simulation
from composed_sim.hosts.callback_guard import CallbackGuard
from composed_sim.hosts.controllers import (EXECUTORS, ROBOTS_PER_PARTICIPANT, HostError, create_controller,
                                             make_executor)
from composed_sim.hosts.lockstep import LoopResult, NodesExchange, TickObserver, run_lockstep
from composed_sim.ros import contract as c
from composed_sim.ros.participants import ignore_participants_of_this_process
from composed_sim.ros.simulator_node import SimulatorNode, robot_devices
from composed_sim.world.schema import World

DISCOVERY_TIMEOUT_S = 60.0
WAIT_SLICE_S = 0.02           # how long one spin_once may wait for a callback while a tick is open


@dataclass
class SetupInfo:
    setup_s: float          # contexts, simulator, nodes, discovery: until tick 0 can start
    nodes: int
    participants: int = 1


class ComposedHost:
    """Context manager owning the rclpy contexts, the nodes and the executor, destroyed in order."""

    def __init__(self, world: World, *, executor: str = "lockstep", domain_id: int = 0,
                 robots_per_participant: int = ROBOTS_PER_PARTICIPANT):
        if executor not in EXECUTORS:
            raise HostError(f"unknown executor {executor!r}; choose one of {', '.join(EXECUTORS)}")
        if robots_per_participant < 1:
            raise HostError(f"robots per participant must be at least 1, got {robots_per_participant}")
        self.world = world
        self.executor_kind = executor
        self.domain_id = domain_id
        self.robots_per_participant = robots_per_participant
        self.contexts: list[Context] = []
        self.sim: Optional[Simulation] = None
        self.simulator_nodes: list[SimulatorNode] = []      # one per shard, in robot order
        self.exchange: Optional[NodesExchange] = None
        self.controllers: list[Node] = []
        self.executor: Optional[Executor] = None
        self.guard: Optional[CallbackGuard] = None
        self._spin_thread: Optional[threading.Thread] = None
        self.setup: Optional[SetupInfo] = None

    def __enter__(self) -> "ComposedHost":
        t0 = time.perf_counter()
        try:
            world = self.world
            classes = {g.controller: plugins.load(g.controller) for g in world.robots}
            self.sim = sim = Simulation(world)
            ignore_participants_of_this_process()
            lockstep = world.lockstep
            self.guard = CallbackGuard(lockstep.watchdog_s, lockstep.unresponsive_s)
            devices, groups = robot_devices(world), world.group_of_robot()
            robots = frozenset(sim.names)
            for shard, start in enumerate(range(0, sim.n, self.robots_per_participant)):
                rows = np.arange(start, min(sim.n, start + self.robots_per_participant))
                context = Context()
                rclpy.init(context=context, domain_id=self.domain_id)
                self.contexts.append(context)
                sim_node = SimulatorNode([sim.names[i] for i in rows], [sim.models[i] for i in rows],
                                         context=context, tick_ns=world.tick_ns, rows=rows,
                                         node_name="composed_sim" if shard == 0 else f"composed_sim_{shard}",
                                         lockstep=lockstep, devices=[devices[i] for i in rows],
                                         rab_payload_bytes=world.range_and_bearing.payload_bytes,
                                         publish_clock=shard == 0)
                sim_node.on_failed.append(self.guard.stop_worker)
                self.simulator_nodes.append(sim_node)
                for i in rows.tolist():
                    name = sim.names[i]
                    node = create_controller(classes[world.robots[groups[i]].controller], name, world,
                                             groups[i], context, robots=robots)
                    self.guard.guard(node, name, sim_node)
                    sim_node.drive_clock_of(node)
                    self.controllers.append(node)
            self.exchange = NodesExchange(self.simulator_nodes)
            self.executor = make_executor(self.executor_kind, self.contexts[0])
            # Simulator nodes last, so that the lockstep executor's one ordered pass runs every
            # controller on its sensors first and then collects the answers they just published.
            for node in (*self.controllers, *self.simulator_nodes):
                self.executor.add_node(node)
            self._wait_for_discovery()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, len(self.controllers) + len(self.simulator_nodes),
                               len(self.contexts))
        return self

    def _wait_for_discovery(self) -> None:
        """Every robot's answer topic has a publisher and its sensors a subscriber before tick 0."""
        deadline = time.monotonic() + DISCOVERY_TIMEOUT_S
        while missing := [r for node in self.simulator_nodes for r in node.unmatched_robots()]:
            if time.monotonic() > deadline:
                raise HostError(f"the controllers of {', '.join(missing[:5])}{' …' if len(missing) > 5 else ''} "
                                f"were not connected within {DISCOVERY_TIMEOUT_S:.0f} s: each must publish "
                                f"{c.CMD_VEL.name} and subscribe to at least one sensor topic")
            time.sleep(0.01)

    def run(self, ticks: Optional[int] = None, *, progress: Optional[Callable[[int], None]] = None,
            should_stop: Callable[[], bool] = lambda: False, observers: Sequence[TickObserver] = ()) -> LoopResult:
        ticks = self.world.length_ticks if ticks is None else ticks
        if self.executor_kind != "multi-threaded":
            wait = self._spin_until_answered
        else:
            # Its callbacks run on its worker threads, as it is made for; the tick loop waits for
            # the simulator node's "all answered".
            self._spin_thread = threading.Thread(target=self._spin, name="executor", daemon=True)
            self._spin_thread.start()
            wait = self.exchange.wait_for_answers
        with self.guard.interrupting_hangs(self._spin_thread is None):
            return run_lockstep(self.sim, self.exchange, wait, ticks, progress=progress,
                                should_stop=should_stop, observers=observers)

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except rclpy.executors.ExternalShutdownException:
            pass

    def _spin_until_answered(self, timeout_s: float) -> bool:
        """Executors driven from this thread: the lockstep executor by design, the EventsExecutor
        because its spin() in a background thread hung in our probes (DESIGN.md), and the
        single-threaded one like them, so that the callback guard can interrupt a hung callback.

        Past the watchdog, the callbacks already queued still run before the tick closes: in one
        thread a late callback delays the ones behind it, and its lateness is its own (the guard
        rejects its answer), not theirs."""
        deadline = time.monotonic() + timeout_s
        drain_left = 4 * len(self.controllers) + 16     # bounded: a busy timer cannot keep the tick open
        idle = 0
        while not self.exchange.all_answered:
            if time.monotonic() < deadline:
                # A constant timeout: a stock executor keeps the ready callbacks of one wait only
                # while spin_once's arguments stay the same, and rebuilds its wait set over every
                # entity otherwise (with a changing timeout: once per callback, 10 s a tick at 320
                # robots). The deadline is then met to within one slice.
                self.executor.spin_once(timeout_sec=WAIT_SLICE_S)
                continue
            before = (self.guard.calls, self.exchange.answered_count)
            self.executor.spin_once(timeout_sec=0)
            drain_left -= 1
            # Twice: a stock executor's spin_once may come back empty once, to rebuild its wait set.
            idle = idle + 1 if (self.guard.calls, self.exchange.answered_count) == before else 0
            if drain_left <= 0 or idle >= 2:
                return False
        return True

    def __exit__(self, *exc) -> None:
        if self.executor is not None:
            self.executor.shutdown()
        if self._spin_thread is not None:
            self._spin_thread.join(timeout=5.0)
        for node in (*self.controllers, *self.simulator_nodes):
            node.destroy_node()
        self.controllers, self.simulator_nodes = [], []
        for context in self.contexts:
            if context.ok():
                rclpy.shutdown(context=context)
        self.contexts = []
