"""The composed host: the simulator and every controller node in one process, one domain, one
executor (``--workers 1``; hosts/workers/worker_host.py spreads the controllers over worker processes).

The robots are split into participant groups (hosting/participant_groups.py); the physics, the
sensing and the tick loop run in this same process.
"""
from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

from composed_sim.core.simulation import Simulation
from composed_sim.hosting import (DEFAULT_EXECUTOR, NodeLogs, ParticipantGroups, ProcessHosting, RelayingExchange,
                                  ROBOTS_PER_PARTICIPANT)
from composed_sim.hosts.base import say_answers_later, HostBase, SetupInfo
from composed_sim.hosts.tick_loop import LoopResult, TickObserver, run_lockstep
from composed_sim.world.schema import World


class ComposedHost(HostBase):
    """Context manager owning the simulation and the participant groups (``Host``)."""

    def __init__(self, world: World, *, executor: str = DEFAULT_EXECUTOR, domain_id: int = 0,
                 robots_per_participant: int = ROBOTS_PER_PARTICIPANT, logs: Optional[NodeLogs] = None):
        """``logs``: the nodes' log lines and tracebacks (hosting/guard/node_logs.py); rclpy's loggers without."""
        self.world = world
        self.domain_id = domain_id
        self.sim: Optional[Simulation] = None
        hosting = ProcessHosting(executor, domain_id, logs.settings if logs is not None else None)
        self.groups = ParticipantGroups(world, 0, len(world.robot_names()), hosting,
                                        robots_per_participant=robots_per_participant, logs=logs)
        self.setup: Optional[SetupInfo] = None

    @property
    def simulator_nodes(self):
        return self.groups.simulator_nodes

    @property
    def controllers(self):
        return self.groups.controllers

    @property
    def exchange(self):
        return self.groups.exchange

    def __enter__(self) -> "ComposedHost":
        t0 = time.perf_counter()
        self.sim = Simulation(self.world)
        self.groups.__enter__()
        say_answers_later(self.groups.answers_later)
        self.setup = SetupInfo(time.perf_counter() - t0, self.groups.nodes, len(self.groups.contexts))
        return self

    def run(self, ticks: Optional[int] = None, *, progress: Optional[Callable[[int], None]] = None,
            should_stop: Callable[[], bool] = lambda: False, observers: Sequence[TickObserver] = (),
            checkpoint: Optional[Callable[[LoopResult], None]] = None, trajectories=None) -> LoopResult:
        ticks = self.world.length_ticks if ticks is None else ticks
        wait, interrupting_hangs = self.groups.start_serving()
        with interrupting_hangs:
            return run_lockstep(self.sim, RelayingExchange(self.groups), wait, ticks, progress=progress,
                                should_stop=should_stop, observers=observers, checkpoint=checkpoint,
                                trajectories=trajectories, logs=self.groups.logs)

    def end_before_exit(self) -> bool:
        return True          # nothing of it lives in another process

    def __exit__(self, *exc) -> None:
        self.groups.__exit__(*exc)
        if self.sim is not None:
            self.sim.close()         # its physics regions' worker processes, if any
