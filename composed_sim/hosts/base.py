"""What every host offers the command line, the benchmark and the tests.

A host runs one world's controllers and its simulator in lockstep. The hosts:

- ``ComposedHost`` (hosts/composed.py): every controller node in this process;
- ``WorkerHost`` (hosts/workers/worker_host.py): the controller nodes in K worker processes, the physics here;
- ``MultiProcessHost`` (hosts/multiprocess/multiprocess_host.py): one process per controller, as in the paper;
- ``RemoteWorkerHost`` (hosts/machines/remote_host.py): worker processes on other machines (``--machines``);
- ``OutsideControllersHost`` (hosts/outside_controllers.py): the simulator alone, driven by processes outside
  the run (``--external-controllers``).

Writing one: make it a context manager that builds everything in ``__enter__`` (a ``Simulation``
as ``sim``, a ``SetupInfo`` as ``setup``) and destroys it in ``__exit__``, also after an
exception; ``run`` is ``hosts/tick_loop.run_lockstep`` over the host's ``Exchange``. Example::

    with ComposedHost(world) as host:
        result = host.run(observers=[RecordingObserver(recorder, Scene(host.sim, world.tick_ns))])
        print(host.setup.setup_s, len(result.violations))
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Callable, Optional, Protocol, Sequence

from composed_sim.core.simulation import Simulation
from composed_sim.hosts.tick_loop import Exchange, LoopResult, TickObserver, run_lockstep
from composed_sim.ros.taps import MessageTap
from composed_sim.world.schema import World


@dataclass
class SetupInfo:
    setup_s: float          # contexts, simulator, nodes, discovery: until tick 0 can start
    nodes: int
    participants: int = 1
    workers: int = 1        # processes hosting the controller nodes (composed mode)


def say_answers_later(robots: Sequence[str]) -> None:
    """The line at start that names the robots with no active cmd_vel publisher yet (a lifecycle
    node not active, a publisher to be made in a callback): each keeps its last command until its
    first answer (hosting/building/wiring.answer_rule), in every host mode alike."""
    if robots:
        shown = ", ".join(robots[:8]) + (f" and {len(robots) - 8} more" if len(robots) > 8 else "")
        print(f"composed-sim: {shown} {'has' if len(robots) == 1 else 'have'} no active cmd_vel publisher yet: "
              f"{'it keeps its' if len(robots) == 1 else 'each keeps its'} last command (none yet: standing) "
              f"until its nodes publish one", file=sys.stderr)


class Host(Protocol):
    world: World
    sim: Simulation
    setup: SetupInfo

    def __enter__(self) -> "Host": ...
    def __exit__(self, *exc) -> None: ...

    def run(self, ticks: Optional[int] = None, *, progress: Optional[Callable[[int], None]] = None,
            should_stop: Callable[[], bool] = lambda: False, observers: Sequence[TickObserver] = (),
            checkpoint: Optional[Callable[[LoopResult], None]] = None, trajectories=None) -> LoopResult:
        """Run ``ticks`` ticks (the world's length by default); stops at a tick boundary once
        ``should_stop()``; every observer sees tick 0 and each tick after; ``checkpoint`` gets the
        result so far every ``lockstep.CHECKPOINT_EVERY`` ticks; ``trajectories``: what records the
        poses (``lockstep.run_lockstep``; default in memory)."""

    @property
    def exchange(self) -> Exchange:
        """The tick loop's exchange (its ``violations`` so far), once the host is entered."""

    def ros_domains(self) -> list[int]:
        """The ROS domains the run uses, lowest first (multi-process mode: a block of them)."""

    def set_message_tap(self, tap: MessageTap) -> None:
        """Hand every per-robot message the tap wants (sensors out, answers in) to it, in this
        process, before the tick it belongs to ends."""

    def observer_node(self):
        """An rclpy Node in this process and the run's domain for live observers (markers)."""

    def workers_peak_rss_mb(self) -> Optional[list[float]]:
        """Each worker process's peak resident memory (the worker host), else None."""

    def workers_rss_mb(self) -> Optional[list[Optional[float]]]:
        """Each worker process's resident memory now (None for one on another machine), else None."""

    def end_before_exit(self) -> bool:
        """Stop what must not outlive this process (worker and controller processes) so that it
        may end now without destroying its nodes (``os._exit``: destroying thousands of nodes one
        by one takes minutes). False: this host must be left through ``__exit__``."""


class HostBase:
    """What the hosts share: their simulator nodes in this process, a run in one ROS domain, no
    worker processes, and leaving through ``__exit__`` (the ``Host`` methods a host of its own
    overrides where it differs)."""
    domain_id: int = 0
    simulator_nodes: list

    def set_message_tap(self, tap: MessageTap) -> None:
        for node in self.simulator_nodes:
            node.set_message_tap(tap)

    def observer_node(self):
        return self.simulator_nodes[0]

    def ros_domains(self) -> list[int]:
        return [self.domain_id]

    def workers_peak_rss_mb(self) -> Optional[list[float]]:
        return None

    def workers_rss_mb(self) -> Optional[list[Optional[float]]]:
        return None

    def end_before_exit(self) -> bool:
        return False


class ControllersElsewhere(HostBase):
    """``Host.run`` for the hosts whose controllers run in other processes (workers, one process
    per controller, controllers outside the run): the tick loop waits on the host's ``exchange``. A host
    whose start-up was interrupted (``_startup_interrupted``) runs no tick and says so."""
    world: World
    sim: Simulation
    exchange: object
    _startup_interrupted: bool = False

    def run(self, ticks: Optional[int] = None, *, progress: Optional[Callable[[int], None]] = None,
            should_stop: Callable[[], bool] = lambda: False, observers: Sequence[TickObserver] = (),
            checkpoint: Optional[Callable[[LoopResult], None]] = None, trajectories=None) -> LoopResult:
        ticks = self.world.length_ticks if ticks is None else ticks
        if self._startup_interrupted:      # stopped before tick 0: an interrupted run of 0 ticks
            should_stop = lambda: True     # noqa: E731 - a stand-in for the caller's callable, one expression
        return run_lockstep(self.sim, self.exchange, self.exchange.wait_for_answers, ticks,
                            progress=progress, should_stop=should_stop, observers=observers,
                            checkpoint=checkpoint, trajectories=trajectories, logs=getattr(self, "logs", None))
