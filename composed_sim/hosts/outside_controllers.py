"""The simulator alone, its robots driven by processes outside the run
(``composed-sim run WORLD --external-controllers``): any process of the run's ROS domain, on this
machine or another, that publishes ``/<robot>/cmd_vel`` is that robot's controller. A vendor's
program started by its own ``main()``, ``ros2 launch``, a real robot's software: nothing to
announce, nothing of composed_sim's to import. The world file's ``controller`` and ``nodes`` of
the robots are not started.

The simulator node, its exchange (``NodesExchange``, spun by a LockstepExecutor in a thread of its
own) and the tick loop are those of the other hosts, so lockstep, the watchdog and the fallbacks
are as on one machine. Before tick 0 it waits until every robot that answers has a controller,
and every endpoint the ROS graph shows on the robot's topics is matched with the simulator's
(``_waiting``), for a moment: a controller's sensor subscriptions are discovered a little after
its publisher, and a subscription matched after tick 0's sensors went out would miss them. During
the run, a robot whose ``cmd_vel`` publisher is gone (its process ended, or DDS lost it after the
participant lease) is marked failed: a violation, then the fallback every tick, never a stall.
"""
from __future__ import annotations

import time
from typing import Callable, Optional

import rclpy
from rclpy.context import Context

from composed_sim.core.simulation import Simulation
from composed_sim.hosts.base import ControllersElsewhere, SetupInfo
from composed_sim.hosting import (HostError, LockstepExecutor, matched_count, NodesExchange, publishes, shut_down,
                                  Spinning)
from composed_sim.hosts.settings import DEFAULT_DISCOVERY_TIMEOUT_S
from composed_sim.hosts.processes import InterruptWatch
from composed_sim.ros import contract as c
from composed_sim.ros.robot_settings import robot_settings
from composed_sim.ros.simulator_node import AnswerTypeError, SimulatorNode
from composed_sim.world.schema import World

GONE_REASON = "its controller is gone (no cmd_vel publisher left)"
SETTLED_S = 0.5         # every robot connected and the graph unchanged this long: tick 0 may start
POLL_S = 0.05
QUIET_CHECK_S = 1.0     # how often robots that are never waited for are looked at for a controller gone


class OutsideExchange(NodesExchange):
    """The exchange with processes outside the run. Whether such a process has anything left to
    do in a tick is its own business, so a robot that answers when published (``answers:
    when_published``) is never waited for: what it published by the tick's close is its answer,
    else it keeps its last command. Its controller being gone would then never show as a late
    answer: ``check_quiet`` looks for it, at most once every QUIET_CHECK_S of wall time."""

    def __init__(self, nodes, check: Callable[[], None], check_quiet: Callable[[], None]):
        super().__init__(nodes, check)
        self._check_quiet = check_quiet
        self._quiet_checked = time.monotonic()

    def wait_for_answers(self, timeout_s: float) -> bool:
        if time.monotonic() - self._quiet_checked >= QUIET_CHECK_S:
            self._check_quiet()
            self._quiet_checked = time.monotonic()
        self.settle_idle()
        return super().wait_for_answers(timeout_s)


class OutsideControllersHost(ControllersElsewhere):
    """Context manager: the simulation, its node and its executor thread; same interface as
    ComposedHost. ``discovery`` only words the errors (the settings are in the environment)."""

    def __init__(self, world: World, *, domain_id: int = 0,
                 discovery_timeout_s: float = DEFAULT_DISCOVERY_TIMEOUT_S, discovery: str = ""):
        if world.nodes:
            raise HostError("--external-controllers: the world's run-wide nodes (nodes:) would be started by "
                            "no one; start them in the run's ROS domain beside the controllers, and leave them "
                            "out of the world file")
        self.world = world
        self.domain_id = domain_id
        self.discovery_timeout_s = discovery_timeout_s
        self.discovery = discovery
        self.sim: Optional[Simulation] = None
        self.sim_node: Optional[SimulatorNode] = None
        self.exchange: Optional[NodesExchange] = None
        self.setup: Optional[SetupInfo] = None
        self._context: Optional[Context] = None
        self._spinning: Optional[Spinning] = None
        self._startup_interrupted = False

    def __enter__(self) -> "OutsideControllersHost":
        t0 = time.perf_counter()
        try:
            self.sim = Simulation(self.world)
            self._context = Context()
            rclpy.init(context=self._context, domain_id=self.domain_id)
            self.sim_node = SimulatorNode(self.sim.names, self.sim.models, context=self._context,
                                          tick_ns=self.world.tick_ns, lockstep=self.world.lockstep,
                                          rab_payload_bytes=self.world.range_and_bearing.payload_bytes,
                                          **robot_settings(self.world, range(self.world.robot_count)))
            with InterruptWatch() as interrupts:
                self._wait_for_controllers(lambda: interrupts.requested)
            self._startup_interrupted = interrupts.requested
            self.exchange = OutsideExchange([self.sim_node], self._check_controllers, self._check_quiet_controllers)
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

    def _wait_for_controllers(self, interrupted: Callable[[], bool]) -> None:
        deadline = time.monotonic() + self.discovery_timeout_s
        settled_since, seen = 0.0, None
        while not interrupted():
            try:
                self.sim_node.detect_answer_types()
            except AnswerTypeError as e:
                raise HostError(str(e)) from None
            doubled = [r for r in self._answering() if self._answer_publishers(r) > 1]
            if doubled:
                raise HostError(f"{_names(doubled)} have more than one cmd_vel publisher: two controllers (or "
                                f"another run in ROS domain {self.domain_id}) drive them")
            waiting = self._waiting()
            now = time.monotonic()
            graph = self._graph()
            if waiting or graph != seen:         # the settling starts again
                settled_since, seen = now, graph
            elif now - settled_since >= SETTLED_S:
                self.sim_node.note_controllers({r: self._answer_gids(r) for r in self._answering()})
                return
            if now > deadline:
                raise HostError(self._discovery_error(waiting))
            time.sleep(POLL_S)

    def _answering(self) -> list[str]:
        """The robots that answer their ticks (a drone's firmware answers its own)."""
        return [r for i, r in enumerate(self.sim.names) if not self.sim_node.by_firmware[i]]

    def _waiting(self) -> list[str]:
        """Robots with no controller yet: no cmd_vel publisher matched, or an endpoint on one of
        their topics that the ROS graph shows but the simulator's side has not matched."""
        return [r for r in self._answering() if self._answer_publishers(r) < 1 or self._unmatched_topics(r)]

    def _unmatched_topics(self, robot: str) -> list[str]:
        node = self.sim_node
        # The other side's endpoints the graph shows: a sensor's subscriptions (the simulator
        # publishes it), the publishers of cmd_vel, leds and rab_tx.
        return [e.topic_name for e in node.robot_endpoints(robot)
                if matched_count(e) < (node.count_subscribers if publishes(e) else node.count_publishers)(e.topic_name)]

    def _graph(self) -> tuple:
        """What the simulator sees of the controllers: each robot's matched counts."""
        return tuple(matched_count(e) for r in self.sim.names for e in self.sim_node.robot_endpoints(r))

    def _discovery_error(self, waiting: list[str]) -> str:
        seen = "; ".join(self._connection_of(r) for r in waiting[:3])
        return (f"no controller connected for {_names(waiting)} after {self.discovery_timeout_s:g} s (seen: {seen}"
                f"{'; …' if len(waiting) > 3 else ''}). With --external-controllers, each robot's controller is "
                f"a process of ROS domain {self.domain_id} that publishes /<robot>/cmd_vel and subscribes to "
                f"the robot's sensor topics{'; discovery: ' + self.discovery if self.discovery else ''} "
                f"(see docs/distributed.md)")

    def _connection_of(self, robot: str) -> str:
        unmatched = self._unmatched_topics(robot)
        said = self.sim_node.connection_of(robot)
        return f"{said}, not matched yet on {', '.join(unmatched)}" if unmatched else said

    # --- the run ----------------------------------------------------------------------------

    def _check_controllers(self) -> None:
        """Called while answers are late: the waited-for robots."""
        self._fail_controllerless(~self.sim_node.answered & ~self.sim_node.failed)

    def _check_quiet_controllers(self) -> None:
        """The robots that answer when published, never waited for."""
        self._fail_controllerless(self.sim_node.when_published & ~self.sim_node.failed)

    def _fail_controllerless(self, rows) -> None:
        """Each robot of ``rows`` (a mask) with no cmd_vel publisher left has lost its controller.
        Matched counts are local to each endpoint (O(1) each)."""
        for i in rows.nonzero()[0]:
            if self._answer_publishers(self.sim.names[i]) == 0:
                self.sim_node.mark_failed(self.sim.names[i], GONE_REASON)

    def _answer_publishers(self, robot: str) -> int:
        """Publishers matched on ``robot``'s cmd_vel (0 while its answer type is not known)."""
        sub = self.sim_node.answer_subscription(robot)
        return 0 if sub is None else sub.get_publisher_count()

    def _answer_gids(self, robot: str) -> list[bytes]:
        """The GIDs of the publishers the ROS graph shows on ``robot``'s cmd_vel: its controller's."""
        topic = c.topic_name(robot, c.CMD_VEL)
        return [bytes(info.endpoint_gid) for info in self.sim_node.get_publishers_info_by_topic(topic)]

    def __exit__(self, *exc) -> None:
        shut_down(self._spinning, [x for x in (self.sim_node,) if x is not None], self._context)
        self._spinning, self.sim_node, self._context = None, None, None
        if self.sim is not None:
            self.sim.close()


def _names(names: list[str]) -> str:
    return ", ".join(names) if len(names) <= 4 else f"{names[0]} … {names[-1]} ({len(names)} robots)"
