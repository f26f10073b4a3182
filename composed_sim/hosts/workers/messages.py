"""The messages between the main process and a worker process (hosts/workers/launcher.py has the
protocol), in a module of their own that both import without the worker's heavy imports."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

EXIT_SETUP = 3          # the block could not be built; the reason went to the main process


@dataclass
class WorkerSetup:
    world: object             # schema World
    start: int                # the block: robots start … stop-1
    stop: int
    index: int                # the worker's number; its participant group has the same
    hosting: object            # hosting/process_hosting.ProcessHosting: its executor, domain, where its robots' logs go
    participant_prefix: bytes  # the GUID prefix of the worker's one participant (hosting/dds/participants.py)
    scratch_dir: str           # where the worker may write its Fast DDS profile
    shared_state: int          # the descriptor of the world's state in shared memory (shared_state.py)


@dataclass
class TickAnswers:
    """A block's answers to a tick; its commands are in the shared state (shared_state.py)."""
    tick: int
    leds: dict = field(default_factory=dict)           # row in the block → [L, 3] uint8
    rab: dict = field(default_factory=dict)            # row in the block → [B] uint8
    violations: list = field(default_factory=list)     # new ones since the last tick: (tick, robot, reason)
    tapped: list = field(default_factory=list)         # (topic, type, bytes, stamp ns)
    run_wide: list = field(default_factory=list)       # (topic, type, bytes) for the next tick's batch
    drones: list = field(default_factory=list)         # the drones' commands of the tick (core/drone_commands.py)
    calls: list = field(default_factory=list)          # calls between places for the next tick (hosting/calls/between_places.py)
    calls_leave: bool = False                          # may its nodes call another place (ParticipantGroups.calls_leave)?
    peak_rss_kb: int = 0                               # the worker's own peak resident memory so far
    another_simulator: Optional[str] = None            # NodesExchange.another_simulator, this tick
    logs: tuple = ()                                   # NodeLogs.drain(): console lines, failures, /rosout
    cpu_s: float = 0.0                                 # the worker's CPU seconds since its first tick
    node_code_s: float = 0.0                           # of which inside its nodes' own code (hosting/guard/node_time.py)
    commands: Optional[tuple] = None                   # a machine's: (linear, angular) of its block (hosts/machines/remote_host.py)


@dataclass
class MachineSetup:
    """What a machine of a distributed run hosts (hosts/machines/agent.py): robots start … stop-1 in
    ``workers`` processes of its own (a number, or "auto" for its cores)."""
    world: object
    start: int
    stop: int
    hosting: object                # as WorkerSetup's
    run_prefix: bytes              # the run's 8 bytes of its workers' GUID prefixes (hosting/dds/participants.py)
    first_group: int               # the participant group number of its first worker (0: the run-wide nodes')
    workers: object
