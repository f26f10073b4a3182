"""The worker host: the controller nodes spread over K worker processes, the physics here.

rclpy holds the GIL in ``publish`` and ``take``, so one process runs its robots' ROS exchange
on one core, whatever the machine. Here the robots are cut into K contiguous blocks; each block
lives in a worker process (hosts/workers/launcher.py) with its participant groups and its own
executor, exactly as the single-process host holds all of them, so every per-robot message stays
inside one participant, through rclpy publish and take, visible to any outside process.

    main process: clock, physics, wheels and odometry, world state, results, recording, observers
       │  once per tick: the world's state →     ← its commands, LEDs, payloads, violations
       ├── worker 1: reads the sensors of robots 0 … b₁-1; their participant group, controllers, executor
       └── worker K: …

Once per tick the main process writes what the sensors read of the world (core/senses.py's
SensingInputs: every robot's pose, LEDs and payload) and the wheels and odometry into shared
memory (hosts/workers/shared_state.py) and wakes each worker with a small message over its socket pair
(``multiprocessing.connection``); each writes its robots' commands back there and sends the rest
of its answers (LEDs, payloads, violations, logs), pickled. Each worker reads its own robots' sensors, so the main
process's serial part does not grow with the sensing; the noise is drawn per robot, tick and
device (devices/common/noise.py), so the same world and seed give the same trajectories for
every K (docs/speed.md, "The main process's tick").

A worker that dies (a controller's segfault, ``os._exit``) or stops answering becomes violations
for its robots only: they are failed (stopped, as any failed robot) and the run goes on.
"""
from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait as wait_for_connections
from pathlib import Path
from typing import Callable, Optional

from composed_sim.core.senses import Senses
from composed_sim.core.simulation import Simulation
from composed_sim.hosting import check_executor, DEFAULT_EXECUTOR, HostError, ProcessHosting, replies, run_prefix
from composed_sim.hosts.base import ControllersElsewhere, SetupInfo, say_answers_later
from composed_sim.hosts.processes import (AdoptedChild, InterruptWatch, become_subreaper, exit_reason,
                                          reap, signal_group)
from composed_sim.hosts.workers.exchange import WorkersExchange
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.hosts.workers.messages import TickAnswers, WorkerSetup
from composed_sim.world.schema import World

STARTUP_TIMEOUT_S = 300.0    # a worker builds hundreds of nodes: minutes at 10 000 robots
STOP_GRACE_S = 2.0           # ("stop",) → SIGKILL


def plan_blocks(n: int, workers: int) -> list[tuple[int, int]]:
    """Cut robots 0 … n-1 into ``workers`` contiguous blocks as even as can be: (start, stop) each."""
    if not 1 <= workers <= n:
        raise ValueError(f"{workers} workers for {n} robots")
    return [(n * w // workers, n * (w + 1) // workers) for w in range(workers)]


def _ending(code: int) -> str:
    """A Popen return code, short: "SIGSEGV", "exit code 3"."""
    if code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"


@dataclass
class Worker:
    index: int
    start: int
    stop: int
    popen: Optional[AdoptedChild]        # None until the launcher reported its pid
    conn: Connection
    log: Path
    answers: Optional[TickAnswers] = None
    dead: Optional[str] = None           # why it is gone (its robots are failed)
    peak_rss_kb: int = 0                 # as it last reported
    last_times: tuple[float, float] = (0.0, 0.0)   # CPU and node-code seconds, as it last reported

    def tail(self, chars: int = 2000) -> str:
        try:
            return self.log.read_text(errors="replace")[-chars:]
        except OSError:
            return ""

    def end(self) -> str:
        """Kill what is left of the worker (its process group) and reap it: why it is gone."""
        signal_group(self.popen, signal.SIGKILL)
        return f"worker process died ({_ending(self.popen.wait())})"

    def startup_failure(self) -> str:
        """It ended before it was ready: what happened, with its last output."""
        return (f"worker {self.index} (robots {self.start}…{self.stop - 1}) ended during start-up "
                f"({exit_reason(self.popen.wait())}):\n{self.tail() or '(no output)'}")


class WorkerHost(ControllersElsewhere):
    """Context manager (``Host``): the simulation here, the controllers in ``workers`` processes;
    every worker stopped and reaped in ``__exit__``."""

    def __init__(self, world: World, *, workers: int, executor: str = DEFAULT_EXECUTOR, domain_id: int = 0,
                 logs=None):
        """``logs``: a ``NodeLogs`` (hosting/guard/node_logs.py): the workers write their robots' log files
        with its settings and send it what the console shows."""
        check_executor(executor)
        self.logs = logs
        n = len(world.robot_names())
        if not 1 <= workers <= n:
            raise HostError(f"--workers {workers}: a worker hosts at least one of the {n} robots "
                            f"(choose 1 … {n}, or auto)")
        self.world = world
        self.domain_id = domain_id
        self.hosting = ProcessHosting(executor, domain_id, logs.settings if logs is not None else None)
        self.blocks = plan_blocks(n, workers)
        self.sim: Optional[Simulation] = None
        self.setup: Optional[SetupInfo] = None
        self.workers: list[Worker] = []
        self.answers_later: list[str] = []      # robots with no active cmd_vel publisher yet (say_answers_later)
        self.run_wide_timers = 0     # the tick of the run-wide nodes' first timer (RunWideNodes.first_timer_tick)
        self.exchange: Optional[WorkersExchange] = None
        self._tmp: Optional[Path] = None
        self.shared: Optional[SharedState] = None
        self._startup_interrupted = False
        self._launcher: Optional[subprocess.Popen] = None     # until it forked the workers
        self._prefix = b""                                     # the run's GUID prefix (run_prefix)
        self._first_group = 0       # the participant group of the first worker (another machine's: not 0)
        self._observer_context = None
        self._observer_node = None

    def __enter__(self) -> "WorkerHost":
        t0 = time.perf_counter()
        try:
            self._tmp = Path(tempfile.mkdtemp(prefix="composed_sim_workers_"))
            self.shared = SharedState(Senses(self.world), self.world.range_and_bearing.payload_bytes)
            self._launch(run_prefix())
            # The launcher imports and forks while this process builds the physics.
            self.sim = Simulation(self.world)
            self._adopt()
            with InterruptWatch() as interrupts:
                ready = self._wait_ready(lambda: interrupts.requested)
            say_answers_later(sorted(self.answers_later, key=self.sim.names.index))
            self._startup_interrupted = interrupts.requested
            nodes = self._open_exchange(ready)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        self.setup = SetupInfo(time.perf_counter() - t0, nodes, len(self.workers), len(self.workers))
        return self

    def _open_exchange(self, ready: tuple, **options) -> int:
        """The tick exchange over the workers, given what ``_wait_ready`` gathered (their nodes,
        run-wide subscriptions and calls between places); returns the number of nodes.
        ``options``: the exchange's own (``grace_s``)."""
        nodes, run_wide, rounds, calls = ready
        self.exchange = WorkersExchange(self.workers, self.sim.names, self.world.lockstep, self.shared, self.logs,
                                        **options)
        self.exchange.run_wide = run_wide
        self.exchange.rounds.needed, self.exchange.rounds.pending = rounds, calls
        return nodes

    def _launch(self, prefix: bytes) -> None:
        """Start the launcher (hosts/workers/launcher.py), which forks the K workers; each waits for
        its block (``_send_setup``)."""
        become_subreaper()
        pairs = [socket.socketpair() for _ in self.blocks]
        fds = [theirs.fileno() for _, theirs in pairs]
        cmd = [sys.executable, "-m", "composed_sim.hosts.workers.launcher", "--fds", ",".join(map(str, fds)),
               "--logs", str(self._tmp), "--parent-pid", str(os.getpid())]
        # Own process group: a terminal's Ctrl-C goes to this process only (which stops the run at
        # a tick boundary). SIGINT blocked while forking, as for the multi-process host's children.
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            with open(self._tmp / "launcher.log", "wb") as log:
                self._launcher = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                                  stderr=log, pass_fds=(*fds, self.shared.fd), process_group=0)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            for _, theirs in pairs:
                theirs.close()
        for index, ((start, stop), (ours, _)) in enumerate(zip(self.blocks, pairs)):
            self.workers.append(Worker(index, start, stop, None, Connection(ours.detach()),
                                       self._tmp / f"worker{index}.log"))
        self._prefix = prefix

    def _send_setup(self, w: Worker) -> None:
        """Tell a worker its block: it builds its nodes now."""
        group = self._first_group + w.index
        w.conn.send(("setup", WorkerSetup(self.world, w.start, w.stop, group, self.hosting,
                                          self._prefix + group.to_bytes(4, "little"), str(self._tmp),
                                          self.shared.fd)))

    def _adopt(self) -> None:
        """The workers' pids, from the launcher once it forked them all and exited."""
        try:
            out, _ = self._launcher.communicate(timeout=STARTUP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise HostError(f"the workers' launcher did not fork them within {STARTUP_TIMEOUT_S:.0f} s") from None
        launcher, self._launcher = self._launcher, None
        pids = out.split()
        if launcher.returncode != 0 or len(pids) != len(self.workers):
            log = (self._tmp / "launcher.log").read_text(errors="replace")[-2000:]
            raise HostError(f"the workers' launcher failed ({exit_reason(launcher.returncode)}):\n"
                            f"{log or '(no output)'}")
        for w, pid in zip(self.workers, pids):
            w.popen = AdoptedChild(int(pid))

    def _wait_ready(self, interrupted: Callable[[], bool], at_once: Optional[int] = None, tick_0: bool = True
                    ) -> tuple[int, list[list], bool, list]:
        """Every worker's nodes built and matched: how many nodes in all, per worker what they
        published on run-wide topics by the run-wide nodes' part of tick 0 (``_start_tick_0``; with
        ``tick_0`` only), whether any may call across places (the ticks then have rounds of calls,
        hosting/calls/rounds.py) and the calls made meanwhile; a worker's set-up error is raised
        here as the error it was (a plugin's names the world file's field). ``at_once``: how many
        build at a time (default: one per usable core)."""
        from composed_sim import plugins
        ready: dict[int, int] = {}      # worker → its nodes
        rounds, calls = False, []
        # At most one worker per core builds its nodes at a time: more would only take turns on
        # the cores and thrash their caches (docs/speed.md, "Set-up").
        cores, sent = at_once or usable_cores(), 0
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while len(ready) < len(self.workers) and not interrupted():
            while sent < len(self.workers) and sent - len(ready) < cores:     # sent, not ready: building
                self._send_setup(self.workers[sent])
                sent += 1
            waiting = {w.conn: w for w in self.workers[:sent] if w.index not in ready}
            if time.monotonic() > deadline:
                raise HostError(f"worker {next(iter(waiting.values())).index} was not ready after "
                                f"{STARTUP_TIMEOUT_S:.0f} s")
            for conn in wait_for_connections(list(waiting), timeout=0.2):
                w = waiting[conn]
                try:
                    message = conn.recv()
                except (EOFError, OSError):
                    raise HostError(w.startup_failure()) from None
                if message[0] == "error":
                    _, kind, text, field, user_traceback = message
                    if kind == "PluginError":
                        raise plugins.PluginError(text, field, user_traceback)
                    raise HostError(text)
                _, ready[w.index], calls_leave, made, later, run_wide_timers = message
                rounds, calls = rounds or calls_leave, calls + made
                self.answers_later += later
                self.run_wide_timers = max(self.run_wide_timers, run_wide_timers)
        run_wide: list[list] = [[] for _ in self.workers]
        if tick_0 and not interrupted():
            run_wide, made = self._start_tick_0(calls, self.run_wide_timers)
            calls += made
        return sum(ready.values()), run_wide, rounds, calls

    def _start_tick_0(self, calls: list, run_wide_timers: int) -> tuple[list[list], list]:
        """What every worker's places serve goes to every worker (a client elsewhere then finds it
        ready, hosting/calls/between_places.py), with the tick of the run-wide nodes' first timer
        (until then the robots may wait for them: ParticipantGroups.note_run_wide_timers); then
        the run-wide nodes' part of tick 0 runs. Per worker what its nodes published on run-wide
        topics by then, and the calls made meanwhile."""
        served = [item for item in calls if item.destination is None]
        for w in self.workers:
            w.conn.send(("served", served, run_wide_timers))
        run_wide: dict[int, list] = {}
        made: list = []

        def lost(w, reason: Optional[str]) -> None:
            raise HostError(w.startup_failure() if reason is None else f"worker {w.index}: {reason}")
        for w, (_, batch, outbox) in replies({w.conn: w for w in self.workers}, STARTUP_TIMEOUT_S, lost,
                                             "its part of tick 0"):
            run_wide[w.index] = batch
            made += outbox
        return [run_wide.get(w.index, []) for w in self.workers], made

    def workers_peak_rss_mb(self) -> list[float]:
        """Each worker's peak resident memory, as last reported with its answers."""
        return [w.peak_rss_kb / 1024 for w in self.workers]

    def workers_rss_mb(self) -> list[Optional[float]]:
        """Each worker's resident memory now, read here (/proc); None for one that is gone or elsewhere."""
        import psutil
        found = []
        for w in self.workers:
            try:
                found.append(psutil.Process(w.popen.pid).memory_info().rss / 2**20 if w.popen is not None else None)
            except psutil.Error:
                found.append(None)
        return found

    def set_message_tap(self, tap) -> None:
        """The workers buffer the tapped messages of a tick and send them with its answers."""
        self.exchange.tap = tap
        for w in self.workers:
            w.conn.send(("tap", list(tap.topics_globs)))

    def end_before_exit(self) -> bool:
        self.__exit__(None, None, None)     # quick: the workers write their logs and end
        return True

    def observer_node(self):
        """A node of this process's own, in the run's domain (the simulator nodes are in the workers)."""
        if self._observer_node is None:
            import rclpy
            from rclpy.context import Context
            from rclpy.node import Node

            from composed_sim.ros.robot_settings import quiet_node_options
            self._observer_context = Context()
            rclpy.init(context=self._observer_context, domain_id=self.domain_id)
            self._observer_node = Node("composed_sim_observers", context=self._observer_context,
                                       **quiet_node_options())
        return self._observer_node

    def __exit__(self, *exc) -> None:
        for w in self.workers:
            if w.dead is None:
                try:
                    w.conn.send(("stop",))
                except OSError:
                    pass
        if self._launcher is not None:      # start-up failed before the workers were adopted
            reap([self._launcher], 0.0)
            self._launcher = None
        reap([w.popen for w in self.workers if w.popen is not None], STOP_GRACE_S)
        for w in self.workers:
            w.conn.close()
        self.workers = []
        if self.sim is not None:
            self.sim.close()         # its physics regions' worker processes, if any
        if self._observer_node is not None:
            import rclpy
            self._observer_node.destroy_node()
            rclpy.shutdown(context=self._observer_context)
            self._observer_node = self._observer_context = None
        if self.shared is not None:      # after the workers: none maps it any more
            self.shared.close()
            self.shared = None
        if self._tmp is not None:
            import shutil
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None


# --workers auto (docs/speed.md, "Workers", has the measurements behind both numbers): below
# this many robots a worker, a process of its own does not pay.
MIN_ROBOTS_PER_WORKER = 64
# A worker's robots share one participant, whose set-up grows with the square of its endpoints;
# fewer workers cost less per tick (each senses its block against the whole swarm, each has its
# DDS threads): above this many robots a worker, more workers set up faster for about the same run.
MAX_ROBOTS_PER_WORKER = 320


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity, e.g. under taskset or a container)."""
    return len(os.sched_getaffinity(0))


def auto_workers(n: int, cores: Optional[int] = None) -> int:
    """K for ``--workers auto``: one process for a small swarm; else one worker per usable core,
    and more where a core's share of robots would make a participant too big to set up quickly.
    The main process needs no core of its own: it steps the physics while the workers wait, and
    waits while they run the controllers."""
    cores = usable_cores() if cores is None else cores
    if n < 2 * MIN_ROBOTS_PER_WORKER:
        return 1
    return max(min(cores, n // MIN_ROBOTS_PER_WORKER), math.ceil(n / MAX_ROBOTS_PER_WORKER))
