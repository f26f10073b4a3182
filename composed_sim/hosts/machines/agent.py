"""A machine's part of a run over machines: the agent that the simulator places on it (a Dask
actor, cluster.py), its block of robots in worker processes of its own.

To the simulator the agent is one worker (launcher.py's messages, one call each); behind it the
machine's workers are the worker host's own, forked by its launcher and sharing the world's state
in this machine's memory (shared_state.py):

    simulator ── per tick: the state its robots read, once ──→ agent ── shared memory ──→ its workers
              ←─ its block's commands and answers, merged ───        ←─ each worker's answers ───

The agent forwards each message to its workers and answers with theirs, merged in robot order: a
tick's answers, or the calls its nodes made when a round of calls between places finds them idle
(rounds.py: the simulator leads the rounds across machines as across workers). A worker of the
machine that dies fails its robots only, as on one machine.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Optional

from composed_sim.core.senses import Senses
from composed_sim.core.violations import FAILED
from composed_sim.hosting import HostError, replies, routed, send_to_live, worker_places
from composed_sim.hosts.processes import last_words
from composed_sim.hosts.workers.exchange import ANSWER_GRACE_S
from composed_sim.hosts.workers.worker_host import WorkerHost, auto_workers, plan_blocks
from composed_sim.hosts.workers.messages import MachineSetup, TickAnswers
from composed_sim.hosts.workers.shared_state import SharedState

# The state's arrays that hold every robot, and those of which a machine gets its block's rows.
ALL_ROBOTS = ("positions", "headings", "led_colors", "rab_payloads")
BLOCK_ROWS = ("wheel_velocities", "wheel_distances", "axis_lengths", "odometry", "odometry_twist")


class MachineWorkers(WorkerHost):
    """This machine's worker processes: the worker host without the simulation."""

    def __init__(self, setup: MachineSetup):
        count = auto_workers(setup.stop - setup.start) if setup.workers == "auto" else \
            min(int(setup.workers), setup.stop - setup.start)
        super().__init__(setup.world, workers=1, executor=setup.hosting.executor, domain_id=setup.hosting.domain_id)
        self.hosting = setup.hosting
        self.blocks = [(setup.start + a, setup.start + b) for a, b in plan_blocks(setup.stop - setup.start, count)]
        self._first_group = setup.first_group

    def start(self, run_prefix: bytes) -> tuple[int, list, bool, list]:
        self._tmp = Path(tempfile.mkdtemp(prefix="composed_sim_machine_"))
        self.shared = SharedState(Senses(self.world), self.world.range_and_bearing.payload_bytes)
        self._launch(run_prefix)
        self._adopt()
        return self._wait_ready(lambda: False, tick_0=False)     # tick 0 starts across machines


class MachineAgent:
    """The actor: ``step(message)`` for each message of the simulator, the machine's reply."""

    def __init__(self):
        self.host: Optional[MachineWorkers] = None
        self.block = slice(0, 0)
        self.tick = 0
        self._lost: list[tuple] = []            # violations of workers lost since the last answers

    def step(self, message):
        kind = message[0]
        if kind == "setup":
            return self._setup(message[1])
        if self.host is None:
            return None
        if kind == "served":            # what every machine's places serve; then tick 0's start
            run_wide, made = self.host._start_tick_0(message[1], message[2])
            return ("run_wide", [m for part in run_wide for m in part], made)
        if kind == "stop":
            return self._stop()
        if kind == "tick":
            self.tick = message[1]
            self._write_state(message[-1])
            message = message[:-1]
        if kind == "calls":
            self._route_calls(message[1])
        else:
            self._forward(lambda k: message)
        return None if kind in ("clock", "tap") else self._collect()

    # --- set-up ------------------------------------------------------------------------------------

    def _setup(self, setup: MachineSetup):
        from composed_sim import plugins
        from composed_sim.interfaces import InterfaceError, activate
        from composed_sim.world.crazyflies import interfaces_needed
        # Its workers claim the run's GUID prefix (the simulator's host id): over UDP only, so that
        # no listener looks for their shared-memory segments on its own machine; and they discover
        # only what is on this machine (unless told otherwise), so two runs here with one domain
        # are the only way to mix (docs/distributed.md).
        os.environ.setdefault("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4")
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.block = slice(setup.start, setup.stop)
        try:
            activate(setup.world.interfaces, interfaces_needed(setup.world))
            self.host = MachineWorkers(setup)
            nodes, run_wide, rounds, calls = self.host.start(setup.run_prefix)
        except (plugins.PluginError, HostError, InterfaceError) as e:
            self._stop()
            return ("error", type(e).__name__, str(e), getattr(e, "field", ()), getattr(e, "user_traceback", ""))
        return ("ready", nodes, rounds, calls, self.host.answers_later, self.host.run_wide_timers)

    def _stop(self) -> None:
        """Its workers stopped and reaped: the run is over for this machine."""
        if self.host is not None:
            self.host.__exit__(None, None, None)
            self.host = None

    # --- a tick -----------------------------------------------------------------------------------

    def _write_state(self, state: dict) -> None:
        views = self.host.shared.views
        for key, value in state.items():
            if key in BLOCK_ROWS:
                views[key][self.block] = value
            else:
                views[key][:] = value

    def _live(self) -> list:
        return [w for w in self.host.workers if w.dead is None]

    def _forward(self, message_for) -> None:
        send_to_live(self.host.workers, message_for, self._lose)

    def _route_calls(self, calls: list) -> None:
        """A round's calls for this machine, to the workers of their places, in the order given."""
        shares = routed(calls, *worker_places(self.host.workers))
        self._forward(lambda k: ("calls", shares[k]))

    def _collect(self):
        """One message from each live worker: all idle (a round's calls) or all answers (the tick's)."""
        lockstep = self.host.world.lockstep
        patience_s = lockstep.watchdog_s + lockstep.unresponsive_s + ANSWER_GRACE_S
        waiting = {w.conn: w for w in self._live()}
        got = dict((w.index, message) for w, message in replies(waiting, patience_s, self._lose,
                                                                 "its answers or a round's calls"))
        if not got:              # the simulator fails the machine's robots that are not yet
            raise HostError("every worker process of this machine is gone: " + "; ".join(
                w.dead for w in self.host.workers))
        if {reply[0] for reply in got.values()} == {"idle"}:
            return ("idle", [c for w in self.host.workers if w.index in got for c in got[w.index][1]])
        return ("answers", self._merged({i: reply[1] for i, reply in got.items() if reply[0] == "answers"}))

    def _merged(self, answers: dict[int, TickAnswers]) -> TickAnswers:
        """The workers' answers as one machine's: rows of the machine's block, in robot order."""
        merged = TickAnswers(self.tick)
        merged.violations, self._lost = self._lost, []
        first, repeats, rosout = [], [], []
        linear, angular = (self.host.shared.views[k][self.block].copy() for k in ("linear", "angular"))
        for w in self.host.workers:
            a = answers.get(w.index)
            if a is None:              # lost: its robots stand, as any failed robot
                rows = slice(w.start - self.block.start, w.stop - self.block.start)
                linear[rows], angular[rows] = 0.0, 0.0
                continue
            offset = w.start - self.block.start
            merged.leds.update({offset + row: colors for row, colors in a.leds.items()})
            merged.rab.update({offset + row: payload for row, payload in a.rab.items()})
            merged.violations += a.violations
            merged.tapped += a.tapped
            merged.run_wide += a.run_wide
            merged.drones += a.drones
            merged.calls += a.calls
            merged.calls_leave = merged.calls_leave or a.calls_leave
            merged.peak_rss_kb += a.peak_rss_kb
            merged.cpu_s += a.cpu_s
            merged.node_code_s += a.node_code_s
            merged.another_simulator = merged.another_simulator or a.another_simulator
            if a.logs:
                first += a.logs[0]
                repeats += a.logs[1]
                rosout += a.logs[2]
        merged.logs = (first, repeats, rosout) if first or repeats or rosout else ()
        merged.commands = (linear, angular)
        return merged

    def _lose(self, w, reason: Optional[str]) -> None:
        """A worker of this machine is gone: its robots are failed, at this tick."""
        if w.dead is not None:
            return
        ended = w.end()
        w.dead = reason or ended
        w.conn.close()
        detail = last_words(w.tail(500))
        names = self.host.world.robot_names()
        self._lost += [(self.tick, names[i], FAILED + w.dead + detail) for i in range(w.start, w.stop)]
