"""The composed host: the simulator node and every controller node in one process, one rclpy
context, one domain, one executor."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import Executor
from rclpy.node import Node

from composed_sim import plugins
from composed_sim.core.simulation import Simulation
from composed_sim.hosts.callback_guard import CallbackGuard
from composed_sim.hosts.controllers import EXECUTORS, HostError, create_controller, make_executor
from composed_sim.hosts.lockstep import LoopResult, TickObserver, run_lockstep
from composed_sim.ros import contract as c
from composed_sim.ros.simulator_node import SimulatorNode, robot_devices
from composed_sim.world.schema import World

DISCOVERY_TIMEOUT_S = 60.0


@dataclass
class SetupInfo:
    setup_s: float          # context, simulator, nodes, discovery: until tick 0 can start
    nodes: int


class ComposedHost:
    """Context manager owning the rclpy context, the nodes and the executor, destroyed in order."""

    def __init__(self, world: World, *, executor: str = "lockstep", domain_id: int = 0):
        if executor not in EXECUTORS:
            raise HostError(f"unknown executor {executor!r}; choose one of {', '.join(EXECUTORS)}")
        self.world = world
        self.executor_kind = executor
        self.domain_id = domain_id
        self.context: Optional[Context] = None
        self.sim: Optional[Simulation] = None
        self.sim_node: Optional[SimulatorNode] = None
        self.controllers: list[Node] = []
        self.executor: Optional[Executor] = None
        self.guard: Optional[CallbackGuard] = None
        self._spin_thread: Optional[threading.Thread] = None
        self.setup: Optional[SetupInfo] = None

    def __enter__(self) -> "ComposedHost":
        t0 = time.perf_counter()
        try:
            classes = {g.controller: plugins.load(g.controller) for g in self.world.robots}
            self.sim = Simulation(self.world)
            self.context = Context()
            rclpy.init(context=self.context, domain_id=self.domain_id)
            lockstep = self.world.lockstep
            self.sim_node = SimulatorNode(self.sim.names, self.sim.models, context=self.context,
                                          tick_ns=self.world.tick_ns, lockstep=lockstep,
                                          devices=robot_devices(self.world),
                                          rab_payload_bytes=self.world.range_and_bearing.payload_bytes)
            self.guard = CallbackGuard(self.sim_node, lockstep.watchdog_s, lockstep.unresponsive_s)
            self.sim_node.on_failed.append(self.guard.stop_worker)
            self.executor = make_executor(self.executor_kind, self.context)
            robots = frozenset(self.sim.names)
            for row, (name, group_index) in enumerate(zip(self.sim.names, self.world.group_of_robot())):
                cls = classes[self.world.robots[group_index].controller]
                node = create_controller(cls, name, self.world, group_index, self.context, robots=robots)
                self.guard.guard(node, name, row)
                self.sim_node.drive_clock_of(node)
                self.controllers.append(node)
                self.executor.add_node(node)
            # Last, so that the lockstep executor's one ordered pass runs every controller on its
            # sensors first and then collects the answers they just published.
            self.executor.add_node(self.sim_node)
            self._wait_for_discovery()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, len(self.controllers) + 1)
        return self

    @property
    def simulator_nodes(self) -> list[SimulatorNode]:
        return [self.sim_node]

    def _wait_for_discovery(self) -> None:
        """Every robot's answer topic has a publisher and its sensors a subscriber before tick 0."""
        deadline = time.monotonic() + DISCOVERY_TIMEOUT_S
        while missing := self.sim_node.unmatched_robots():
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
            wait = self.sim_node.wait_for_answers
        with self.guard.interrupting_hangs(self._spin_thread is None):
            return run_lockstep(self.sim, self.sim_node, wait, ticks, progress=progress,
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
        while not self.sim_node.all_answered:
            remaining = deadline - time.monotonic()
            if remaining > 0:
                self.executor.spin_once(timeout_sec=remaining)
                continue
            before = (self.guard.calls, self.sim_node.answered_count)
            self.executor.spin_once(timeout_sec=0)
            drain_left -= 1
            # Twice: a stock executor's spin_once may come back empty once, to rebuild its wait set.
            idle = idle + 1 if (self.guard.calls, self.sim_node.answered_count) == before else 0
            if drain_left <= 0 or idle >= 2:
                return False
        return True

    def __exit__(self, *exc) -> None:
        if self.executor is not None:
            self.executor.shutdown()
        if self._spin_thread is not None:
            self._spin_thread.join(timeout=5.0)
        for node in self.controllers:
            node.destroy_node()
        self.controllers = []
        if self.sim_node is not None:
            self.sim_node.destroy_node()
            self.sim_node = None
        if self.context is not None and self.context.ok():
            rclpy.shutdown(context=self.context)
        self.context = None
