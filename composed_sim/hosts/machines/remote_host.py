"""Remote workers: the simulation here, the robots on other machines (``composed-sim run WORLD
--machines M``, and on each machine ``composed-sim join ADDRESS``).

The worker host over machines instead of local processes: the robots are cut into M blocks, one
per machine, and each machine's agent (agent.py) is one worker to the tick loop, the rounds of
calls and the answers (hosts/workers/exchange.py's WorkersExchange and hosting/calls/rounds.py,
unchanged). What differs is only what a message carries: the world's state is not in this machine's memory there, so each tick's
message takes it along, once per machine (``block_state``: every robot's pose, 24 bytes; the LEDs
and payloads only when they changed; the block's wheels and odometry, 72 bytes a robot), and the
answers bring the block's commands back into this process's shared state, where the tick loop reads
them as from local workers. The engine is Dask (cluster.py).

A machine lost (its process killed, its network gone) fails its robots only, as a worker that
dies: the scheduler reports it at once when its connection closes, after the watchdog when it goes
silent. A machine that does not join within the timeout is named, with the command to run there.
"""
from __future__ import annotations

import getpass
import os
import secrets
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from composed_sim.core.senses import Senses
from composed_sim.core.simulation import Simulation
from composed_sim.hosting import DEFAULT_EXECUTOR, HostError, run_prefix
from composed_sim.hosts.base import SetupInfo, say_answers_later
from composed_sim.hosts.processes import InterruptWatch
from composed_sim.hosts.machines.agent import ALL_ROBOTS, BLOCK_ROWS, MachineAgent
from composed_sim.hosts.machines import credentials as run_credentials
from composed_sim.hosts.machines.cluster import ActorConnection, Machine, RunScheduler
from composed_sim.hosts.settings import LinkSecurity
from composed_sim.hosts.workers.exchange import ANSWER_GRACE_S
from composed_sim.hosts.workers.worker_host import Worker, WorkerHost, plan_blocks
from composed_sim.hosts.workers.messages import MachineSetup
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.world.schema import World

# A machine's agent waits for its own workers as this process waits for local ones; this process
# waits that much longer for the machine (the network, the agent's merging).
MACHINE_GRACE_S = 2 * ANSWER_GRACE_S
GROUPS_PER_MACHINE = 1 << 16     # participant group numbers: machine i's workers are i·2¹⁶ + k
DEFAULT_JOIN_TIMEOUT_S = 120.0


def block_state(views: dict, block: slice, sent: dict) -> dict:
    """What a machine needs of the state this tick: every robot's pose; LEDs, payloads and axis
    lengths only when they changed since ``sent`` (updated here); its block's wheels and odometry."""
    state = {"positions": views["positions"], "headings": views["headings"]}
    for key in ("led_colors", "rab_payloads", "axis_lengths"):
        value = views[key] if key in ALL_ROBOTS else views[key][block]
        if key not in sent or not np.array_equal(sent[key], value):
            state[key] = sent[key] = value.copy()
    for key in ("altitudes", "supervisor_info"):    # drones' (core/flight.py): none sent while all are 0
        value = views[key]
        if (key in sent or value.any()) and not np.array_equal(sent.get(key), value):
            state[key] = sent[key] = value.copy()
    for key in BLOCK_ROWS:
        if key != "axis_lengths":
            state[key] = views[key][block]
    return state


class MachineLink(ActorConnection):
    """The connection to a machine's agent: a tick's message takes the machine's state along, the
    answers' commands go into this process's shared state."""

    def __init__(self, actor, loop, forget, shared: SharedState, block: slice):
        super().__init__(actor, loop, forget)
        self._shared, self._block, self._sent = shared, block, {}
        self.bytes_sent = 0           # the state's payload, for the benchmark

    def send(self, message) -> None:
        if message[0] == "tick":
            state = block_state(self._shared.views, self._block, self._sent)
            self.bytes_sent += sum(v.nbytes for v in state.values())
            message = (*message, state)
        super().send(message)

    def recv(self):
        message = super().recv()
        if message[0] == "answers" and message[1].commands is not None:
            linear, angular = message[1].commands
            self._shared.views["linear"][self._block], self._shared.views["angular"][self._block] = linear, angular
        return message


@dataclass
class RemoteWorker(Worker):
    """A machine, as one worker of the worker host; its ``conn`` is a MachineLink."""
    machine: Optional[Machine] = None

    def tail(self, chars: int = 2000) -> str:
        return ""

    def end(self) -> str:
        self.conn.forget()
        return f"machine {self.machine.ip} ({self.machine.host}) lost: {self.conn.gone}"

    def startup_failure(self) -> str:
        return (f"machine {self.machine.ip} ({self.machine.host}, robots {self.start}…{self.stop - 1}) was lost "
                f"during start-up: {self.conn.gone}")


class RemoteWorkerHost(WorkerHost):
    """Context manager (``Host``): the simulation here, the controllers on ``machines`` other
    machines (a number, or their addresses or host names in block order)."""

    def __init__(self, world: World, *, machines: Union[int, list[str]], listen: str = "0.0.0.0:0",
                 link: LinkSecurity = LinkSecurity(), executor: str = DEFAULT_EXECUTOR, domain_id: int = 0,
                 logs=None, join_timeout_s: float = DEFAULT_JOIN_TIMEOUT_S,
                 announce: Optional[Callable[[str], None]] = None):
        """``link``: mutual TLS (the default: credentials of the run's own, written into
        ``link.fresh_into`` or a temporary folder) or plain tcp://. ``announce(line)``: where the
        command for the other machines, each join and each refused peer are said (the console)."""
        count = machines if isinstance(machines, int) else len(machines)
        if count > len(world.robot_names()):
            raise HostError(f"--machines {count}: a machine hosts at least one of the {len(world.robot_names())} "
                            f"robots")
        super().__init__(world, workers=count, executor=executor, domain_id=domain_id, logs=logs)
        self.machines = machines
        self.listen, self.link, self.join_timeout_s = listen, link, join_timeout_s
        self.announce = announce or (lambda line: print(line, file=sys.stderr, flush=True))
        self.run_id = secrets.token_hex(4)
        self.scheduler: Optional[RunScheduler] = None
        self.credentials: Optional[run_credentials.Credentials] = None
        self._credentials_dir: Optional[tempfile.TemporaryDirectory] = None

    @property
    def join_command(self) -> str:
        guard = "--insecure" if self.credentials is None else f"--credentials {self.credentials.path}"
        return f"composed-sim join {self.scheduler.address} --run {self.run_id} {guard}"

    def _run_credentials(self) -> Optional[run_credentials.Credentials]:
        """The run's credentials: the file given, or new ones; None over plain tcp://."""
        if self.link.insecure:
            self.announce(f"composed-sim: --insecure: the run listens on plain tcp:// at {self.listen}, neither "
                          f"authenticated nor encrypted: whoever reaches that port can run code in this process "
                          f"as {getpass.getuser()}, and read or change the run")
            return None
        if self.link.credentials is not None:
            try:
                return run_credentials.load(Path(self.link.credentials))
            except HostError as e:
                raise HostError(f"--credentials {e}") from None
        folder = self.link.fresh_into
        if folder is None:      # a host built by a program, not the command line: gone with the run
            self._credentials_dir = tempfile.TemporaryDirectory(prefix="composed_sim-credentials-")
            folder = self._credentials_dir.name
        return run_credentials.make(Path(folder) / run_credentials.FILE_NAME)

    def __enter__(self) -> "RemoteWorkerHost":
        t0 = time.perf_counter()
        try:
            self.shared = SharedState(Senses(self.world), self.world.range_and_bearing.payload_bytes,
                                      share_tree=False)       # the machines get the state without it
            self.sim = Simulation(self.world)
            # Half the watchdog, checked every half: a silent machine is lost within one watchdog.
            self.credentials = self._run_credentials()
            self.scheduler = RunScheduler(self.listen, self.run_id, self.world.lockstep.watchdog_s / 2,
                                          self.credentials, self.announce)
            self.announce(f"composed-sim: waiting for {len(self.blocks)} machines; on each: {self.join_command}")
            with InterruptWatch() as interrupts:
                joined = self.scheduler.wait_for(self.machines, self.join_timeout_s, lambda: interrupts.requested,
                                                 self.join_command)
                if joined:
                    self._place(joined)
                    ready = self._wait_ready(lambda: interrupts.requested, at_once=len(self.workers))
                    say_answers_later(sorted(self.answers_later, key=self.sim.names.index))
            self._startup_interrupted = interrupts.requested
            if self._startup_interrupted:
                ready = 0, [[] for _ in self.workers], False, []
            nodes = self._open_exchange(ready, grace_s=MACHINE_GRACE_S)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, nodes, len(self.workers), len(self.workers))
        return self

    def _place(self, joined: list[Machine]) -> None:
        self._prefix = run_prefix()
        self.blocks = plan_blocks(self.sim.n, len(joined))
        for index, (machine, (start, stop)) in enumerate(zip(joined, self.blocks)):
            link = self.scheduler.place(MachineAgent, machine, f"composed_sim-{self.run_id}-machine{index}",
                                        lambda *actor, block=slice(start, stop): MachineLink(*actor, self.shared, block))
            self.workers.append(RemoteWorker(index, start, stop, None, link, Path(os.devnull), machine=machine))

    def _send_setup(self, w: RemoteWorker) -> None:
        w.conn.send(("setup", MachineSetup(self.world, w.start, w.stop, self.hosting, self._prefix,
                                           w.index * GROUPS_PER_MACHINE, w.machine.workers)))

    def placement(self) -> str:
        """Which machine hosts which robots, in words."""
        return f"{len(self.workers)} machines: " + ", ".join(
            f"{w.machine.ip} ({w.machine.host}) robots {w.start}-{w.stop - 1}" for w in self.workers)

    def bytes_sent_per_tick(self, ticks: int) -> float:
        """The state's payload sent to the machines per tick (what the wire carries besides Dask's framing)."""
        return sum(w.conn.bytes_sent for w in self.workers) / max(ticks, 1)

    def __exit__(self, *exc) -> None:
        super().__exit__(*exc)
        if self.scheduler is not None:
            self.scheduler.close()
            self.scheduler = None
        if self._credentials_dir is not None:
            self._credentials_dir.cleanup()
            self._credentials_dir = None
