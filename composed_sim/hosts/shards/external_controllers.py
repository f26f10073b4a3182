"""The simulator alone, its controllers hosted by shards on this or other machines
(``composed-sim run WORLD --external-controllers``; the shards: ``composed_sim.hosts.shards.shard_host``).

The simulator node and the tick loop are the composed host's; the exchange is multi-process mode's
``NodesExchange`` over the one simulator node, spun by a LockstepExecutor in its own thread, so
lockstep, the shared watchdog and the fallbacks are exactly as on one machine. Before tick 0 it
waits until every robot is hosted by exactly one shard of the same world whose endpoints are
matched on both sides (the shard announces when its side is). During the run, a robot whose
``cmd_vel`` publisher has disappeared (its shard ended, or DDS lost it after the participant
lease) is marked failed: a violation, then the fallback every tick, never a stall.
"""
from __future__ import annotations

import time
from typing import Callable, Optional

import rclpy
from rclpy.context import Context

from composed_sim.core.simulation import Simulation
from composed_sim.hosts.base import ControllersElsewhere, SetupInfo
from composed_sim.hosting import HostError, LockstepExecutor, matched, NodesExchange, shut_down, Spinning
from composed_sim.hosts.settings import DEFAULT_DISCOVERY_TIMEOUT_S
from composed_sim.hosts.processes import InterruptWatch
from composed_sim.hosts.shards.robot_ranges import format_ranges
from composed_sim.hosts.shards.announce import ShardInfo, ShardRegistry, world_fingerprint
from composed_sim.ros import contract as c
from composed_sim.ros.robot_settings import robot_settings
from composed_sim.ros.simulator_node import AnswerTypeError, SimulatorNode
from composed_sim.world.schema import World

GONE_REASON = "its shard is gone (no cmd_vel publisher left)"


class ExternalControllersHost(ControllersElsewhere):
    """Context manager: the simulation, its node and its executor thread; same interface as
    ComposedHost. ``discovery`` only words the errors (the settings are in the environment)."""

    def __init__(self, world: World, *, domain_id: int = 0,
                 discovery_timeout_s: float = DEFAULT_DISCOVERY_TIMEOUT_S, discovery: str = ""):
        self.world = world
        self.domain_id = domain_id
        self.discovery_timeout_s = discovery_timeout_s
        self.discovery = discovery
        self.sim: Optional[Simulation] = None
        self.sim_node: Optional[SimulatorNode] = None
        self.exchange: Optional[NodesExchange] = None
        self.shards: dict[str, ShardInfo] = {}
        self.setup: Optional[SetupInfo] = None
        self._context: Optional[Context] = None
        self._registry: Optional[ShardRegistry] = None
        self._spinning: Optional[Spinning] = None
        self._startup_interrupted = False

    def __enter__(self) -> "ExternalControllersHost":
        t0 = time.perf_counter()
        try:
            self.sim = Simulation(self.world)
            self._context = Context()
            rclpy.init(context=self._context, domain_id=self.domain_id)
            self.sim_node = SimulatorNode(self.sim.names, self.sim.models, context=self._context,
                                          tick_ns=self.world.tick_ns, lockstep=self.world.lockstep,
                                          rab_payload_bytes=self.world.range_and_bearing.payload_bytes,
                                          **robot_settings(self.world, range(self.world.robot_count)))
            endpoints = self.sim_node.endpoints_by_topic()
            self._registry = ShardRegistry(self._context, self.sim.n)
            with InterruptWatch() as interrupts:
                self._wait_for_shards(endpoints, lambda: interrupts.requested)
            self._startup_interrupted = interrupts.requested
            self.exchange = NodesExchange([self.sim_node], self._check_shards)
            self._spinning = Spinning(LockstepExecutor(context=self._context))
            self._spinning.executor.add_node(self.sim_node)
            self._spinning.start_thread()
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, 1)
        return self

    @property
    def simulator_nodes(self) -> list[SimulatorNode]:
        return [self.sim_node]

    # --- before tick 0 ----------------------------------------------------------------------

    def _wait_for_shards(self, endpoints: dict, interrupted: Callable[[], bool]) -> None:
        names = self.sim.names
        fingerprint = world_fingerprint(self.world)
        deadline = time.monotonic() + self.discovery_timeout_s
        while not interrupted():
            self.shards = self._registry.poll()
            if self._registry.malformed:
                raise HostError(f"a controller shard does not fit this world: {self._registry.malformed[0]}")
            other = [s for s in self.shards.values() if s.world != fingerprint]
            if other:
                raise HostError(f"controller shard {other[0].shard} (robots {format_ranges(other[0].robots)}) was "
                                f"built from another world: start it with the same world file and the same "
                                f"--seed and robot count as the simulator")
            host_of: dict[int, ShardInfo] = {}
            for info in self.shards.values():     # arrival order: a restarted shard replaces its predecessor
                host_of.update({i: info for i in info.robots})
            try:
                unmatched_sim_side = set(names.index(r) for r in self.sim_node.unmatched_robots())
            except AnswerTypeError as e:
                raise HostError(str(e)) from None
            doubled = [i for i in range(self.sim.n) if self._answer_publishers(i) > 1]
            if doubled:
                raise HostError(f"robots {format_ranges(doubled)} have more than one cmd_vel publisher: "
                                f"two shards (or another run in ROS domain {self.domain_id}) host them")
            unmatched_sim_side |= {i for i, info in host_of.items()
                                   if not all(matched(endpoints.get(c.topic_name(names[i], c.TOPICS[t])))
                                              for t in info.topics.get(i, []) if t in c.TOPICS)}
            missing = [i for i in range(self.sim.n) if i not in host_of]
            if not missing and not unmatched_sim_side:
                self.sim_node.note_controllers({names[i]: info.gids.get(i, []) for i, info in host_of.items()})
                return
            if time.monotonic() > deadline:
                raise HostError(self._discovery_error(missing, sorted(unmatched_sim_side - set(missing))))
            time.sleep(0.02)

    def _discovery_error(self, missing: list[int], unmatched: list[int]) -> str:
        names = self.sim.names
        found = "; ".join(f"{s.shard} hosts {format_ranges(s.robots)}" for s in self.shards.values()) or "none"
        parts = []
        if missing:
            parts.append(f"no controller shard hosts robots {format_ranges(missing)} ({_names(names, missing)})")
        if unmatched:
            seen = "; ".join(self.sim_node.connection_of(names[i]) for i in unmatched[:3])
            parts.append(f"robots {format_ranges(unmatched)} are announced but their topics are not matched here "
                         f"(seen: {seen}{'; …' if len(unmatched) > 3 else ''})")
        return (f"{' and '.join(parts)} after {self.discovery_timeout_s:g} s (shards found: {found}). Start "
                f"`composed-sim host WORLD --robots {format_ranges(missing or unmatched)}` with the same world "
                f"in ROS domain {self.domain_id}{'; discovery: ' + self.discovery if self.discovery else ''} "
                f"(see docs/distributed.md)")

    # --- the run ----------------------------------------------------------------------------

    def _check_shards(self) -> None:
        """Called while answers are late: a waited-for robot with no cmd_vel publisher left has
        lost its shard. Matched counts are local to each endpoint (O(1) each)."""
        node = self.sim_node
        waiting = ~node.answered & ~node.failed
        for i in waiting.nonzero()[0]:
            if self._answer_publishers(i) == 0:
                node.mark_failed(self.sim.names[i], GONE_REASON)

    def _answer_publishers(self, i: int) -> int:
        """Publishers matched on robot i's cmd_vel (0 while its answer type is not known)."""
        sub = self.sim_node.answer_subscription(self.sim.names[i])
        return 0 if sub is None else sub.get_publisher_count()

    def __exit__(self, *exc) -> None:
        shut_down(self._spinning, [x for x in (self._registry, self.sim_node) if x is not None], self._context)
        self._spinning, self._registry, self.sim_node, self._context = None, None, None, None
        if self.sim is not None:
            self.sim.close()


def _names(names: list[str], rows: list[int]) -> str:
    return ", ".join(names[i] for i in rows) if len(rows) <= 4 else f"{names[rows[0]]} … {names[rows[-1]]}"
