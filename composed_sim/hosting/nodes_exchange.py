"""The tick loop's ``Exchange`` (hosts/tick_loop.py) over the simulator nodes of this process: the
composed host's participant groups, multi-process mode's domains, a distributed run's simulator."""
from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

import numpy as np

from composed_sim.core.simulation import SensorFrame
from composed_sim.core.violations import Violation
from composed_sim.hosting.guard.node_time import NodeTime
from composed_sim.hosting.run_wide.relay import Message
from composed_sim.ros.simulator_node import SimulatorNode


class NodesExchange:
    """The ``Exchange`` over several SimulatorNodes (the composed host's participant groups, one per DDS
    participant; the multi-process host's domains): each node publishes and collects its own
    robots, writing into the shared (simulation-row) command arrays."""

    POLL_S = 0.01   # while waiting for answers, call ``check`` this often
    senses_itself = False

    def __init__(self, nodes: Sequence[SimulatorNode], check: Callable[[], None] = lambda: None,
                 node_time: Optional[NodeTime] = None):
        """``check``: looks for what can settle a robot besides an answer, e.g. a dead child
        process (it marks its robot failed, so it is not waited for). ``node_time``: the time
        spent in the nodes' own code, where they run in this process (composed mode)."""
        self.nodes = list(nodes)
        self._check = check
        self._node_time = node_time
        self.drone_commands: list = []     # the tick's (hosting/drones.py), set by its close

    @property
    def violations(self) -> list[Violation]:
        # Stable sort: per tick, in node order, each node's in the order they happened.
        return sorted((v for n in self.nodes for v in n.violations), key=lambda v: v.tick)

    @property
    def all_answered(self) -> bool:
        return all(n.all_answered for n in self.nodes)

    @property
    def answered_count(self) -> int:
        return sum(n.answered_count for n in self.nodes)

    @property
    def waiting_on_quiet_robots(self) -> bool:
        """Is a robot that answers when published (``answers: when_published``) still open?"""
        return any((n.when_published & ~n.answered & ~n.failed).any() for n in self.nodes)

    def settle_idle(self, robots=None) -> int:
        """Those robots' nodes (or those of them in ``robots``) have nothing left to do in the
        tick: they keep their last command."""
        return sum(n.settle_idle(None if robots is None else [r for r in n.robots if r in robots])
                   for n in self.nodes)

    def publish_tick(self, frame: SensorFrame) -> None:
        for node in self.nodes:
            node.publish_tick(frame)

    def gathering_s(self) -> float:
        return 0.0      # the answers arrive through the executor's callbacks, counted as waiting

    def controllers_time_s(self) -> tuple[float, float]:
        return 0.0, self._node_time.seconds if self._node_time is not None else 0.0

    def publish_clock(self, tick: int) -> None:
        for node in self.nodes:
            node.publish_clock(tick)

    def another_simulator(self) -> Optional[str]:
        return next((other for node in self.nodes if (other := node.another_simulator()) is not None), None)

    def wait_for_answers(self, timeout_s: float) -> bool:
        """Until every node's robots answered (their callbacks run elsewhere: executor threads,
        other processes), under one watchdog deadline for all."""
        deadline = time.monotonic() + timeout_s
        while True:
            pending = [n for n in self.nodes if not n.all_answered]
            if not pending:
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            if not pending[0].wait_for_answers(min(remaining, self.POLL_S)):
                self._check()

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        for node in self.nodes:
            node.close_tick(fallback, previous, commands)

    def take_led_commands(self) -> dict[int, np.ndarray]:
        out: dict[int, np.ndarray] = {}
        for node in self.nodes:
            out.update(node.take_led_commands())
        return out

    def take_rab_payloads(self) -> dict[int, np.ndarray]:
        out: dict[int, np.ndarray] = {}
        for node in self.nodes:
            out.update(node.take_rab_payloads())
        return out

    def take_drone_commands(self) -> list:
        """The commands the drones' endpoints took in the tick (core/drone_commands.py)."""
        taken, self.drone_commands = self.drone_commands, []
        return taken


class RelayingExchange(NodesExchange):
    """The simulator nodes of every robot's participant groups (the composed host's), and their
    run-wide relay: each tick opens with the run-wide messages of the tick before (hosting/run_wide/relay.py).
    A worker process does the same steps itself, its batches coming from the main process."""

    def __init__(self, groups):
        super().__init__(groups.simulator_nodes, node_time=groups.node_time)
        self._groups = groups
        self._batch: Optional[list[Message]] = None     # what opens the next tick
        self._tick = 0

    def publish_tick(self, frame: SensorFrame) -> None:
        if self._batch is None:               # tick 0: what the nodes published while being built
            self._batch = self._groups.close_run_wide(frame.tick)
        self._tick = frame.tick
        self._groups.open_tick(frame.tick, self._batch)
        super().publish_tick(frame)

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        super().close_tick(fallback, previous, commands)
        self.drone_commands = self._groups.take_drone_commands()     # before the next tick's run-wide part
        self._batch = self._groups.close_run_wide(self._tick + 1)
