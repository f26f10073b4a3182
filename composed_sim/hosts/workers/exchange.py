"""The tick's exchange over the worker processes (hosts/workers/worker_host.py): a tick's state goes
out once, to every worker; their answers come back as arrays and the lists of their violations."""
from __future__ import annotations

import time
from typing import Optional

import numpy as np

from composed_sim.core.simulation import Simulation
from composed_sim.core.violations import FAILED, Violation
from composed_sim.hosting import PipeRounds, replies
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.hosts.processes import last_words

# Past the watchdog a worker still drains its queued callbacks, and interrupts a hung one after
# unresponsive_s; only a worker stuck beyond that (a callback blocked in C) is given up on.
ANSWER_GRACE_S = 5.0


class WorkersExchange:
    """The ``Exchange`` over the worker processes: a tick's frame goes out in blocks, the answers
    come back as arrays; the per-node violation lists keep the single-process order."""

    def __init__(self, workers: list, names: list[str], lockstep, shared: SharedState, logs=None,
                 grace_s: float = ANSWER_GRACE_S):
        self.workers = workers
        self.shared = shared         # the world's state and the commands (shared_state.py)
        self.logs = logs             # NodeLogs: the workers' console lines merge here
        self._names = names
        self._violations: list[list[Violation]] = [[] for _ in workers]   # per worker, as they happened
        self._failed = np.zeros(len(names), dtype=bool)
        self._lockstep = lockstep
        self._tick = 0
        self.tap = None
        # The run-wide messages that open the next tick (hosting/run_wide/relay.py): the workers' parts in
        # worker order, i.e. robot order, the run-wide nodes' (worker 0's) first.
        self.run_wide: list[list] = [[] for _ in workers]
        self._gathering_s = 0.0
        self._sent: dict = {}        # the scene, floor and lights the workers have now
        self._grace_s = grace_s       # past the watchdog and a hung callback's interruption
        self.rounds = PipeRounds(workers, lockstep.watchdog_s + lockstep.unresponsive_s + grace_s, self._lost)

    def gathering_s(self) -> float:
        return self._gathering_s

    def controllers_time_s(self) -> tuple[float, float]:
        """The workers' CPU and node-code seconds since their first tick, as they last reported."""
        reported = [w.last_times for w in self.workers]
        return sum(cpu for cpu, _ in reported), sum(code for _, code in reported)

    @property
    def violations(self) -> list[Violation]:
        # Stable sort by tick over the workers in robot order: the single-process host's order.
        return sorted((v for per_worker in self._violations for v in per_worker), key=lambda v: v.tick)

    senses_itself = True

    def publish_state(self, sim: Simulation) -> None:
        """What the sensors read this tick and every robot's wheels and odometry, into the shared
        state (each worker reads its block's sensors from it); a small message wakes each worker."""
        inputs = sim.sensing_inputs()
        self._tick = inputs.tick
        self.shared.write(inputs, sim.robot_rows())
        # What rarely changes (the scene without movable objects, the floor, the lights) is sent
        # only when it did; a worker keeps the last it got.
        changed = {name: value for name, value in (("scene", inputs.scene), ("floor", inputs.floor),
                                                   ("lights", inputs.lights))
                   if name not in self._sent or self._sent[name] is not value}
        self._sent.update(changed)
        message = ("tick", inputs.tick, inputs.route_messages, changed, [m for part in self.run_wide for m in part],
                   self.rounds.needed)
        for w in self.workers:
            w.answers = None
            if w.dead is None:
                try:
                    w.conn.send(message)
                except OSError:
                    self._lost(w)
        if self.rounds.needed:
            self.rounds.run()           # the calls that reached the robots at the tick's start

    def publish_clock(self, tick: int) -> None:
        for w in self.workers:
            if w.dead is None:
                try:
                    w.conn.send(("clock", tick))
                except OSError:
                    self._lost(w)

    def another_simulator(self) -> Optional[str]:
        """What a worker's simulator node found with this tick's answers (each worker sees its own
        /clock publisher only: the workers' participants ignore one another)."""
        return next((w.answers.another_simulator for w in self.workers
                     if w.dead is None and w.answers is not None and w.answers.another_simulator), None)

    def wait_for_answers(self, timeout_s: float) -> bool:
        """Until every live worker sent its answers. Each worker applies the watchdog itself; one
        that is not back well after it (or whose socket closed: it died) is given up."""
        patience_s = timeout_s + self._lockstep.unresponsive_s + self._grace_s
        if self.rounds.needed:
            self.rounds.run()           # the tick's calls between places, until none is in flight
        pending = {w.conn: w for w in self.workers if w.dead is None and w.answers is None}
        for w, (_, answers) in replies(pending, patience_s, self._lost, "the tick's answers"):
            started = time.perf_counter()
            w.answers = answers
            w.peak_rss_kb = answers.peak_rss_kb
            w.last_times = answers.cpu_s, answers.node_code_s
            self.run_wide[w.index] = answers.run_wide
            self.rounds.pending += answers.calls
            self.rounds.needed = self.rounds.needed or answers.calls_leave
            self._violations[w.index].extend(Violation(*v) for v in answers.violations)
            if self.logs is not None and answers.logs:
                self.logs.merge(answers.logs)
            if self.tap is not None:
                for topic, msgtype, data, stamp_ns in answers.tapped:
                    self.tap.write_serialized(topic, msgtype, data, stamp_ns)
            self._gathering_s += time.perf_counter() - started
        return True

    def _lost(self, w, reason: Optional[str] = None) -> None:
        """A worker is gone: its robots are failed, once each, at this tick."""
        if w.dead is not None:
            return
        ended = w.end()        # whatever the reason: what is left of it is killed
        reason = ended if reason is None else reason
        w.dead = reason
        w.conn.close()
        detail = last_words(w.tail(500))
        for i in range(w.start, w.stop):
            if not self._failed[i]:
                self._failed[i] = True
                self._violations[w.index].append(Violation(self._tick, self._names[i], FAILED + reason + detail))

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        for w in self.workers:
            block = slice(w.start, w.stop)
            if w.answers is None:           # gone: stopped, as any failed robot
                commands[0][block], commands[1][block] = 0.0, 0.0
            else:
                commands[0][block], commands[1][block] = self.shared.views["linear"][block], \
                    self.shared.views["angular"][block]

    def take_led_commands(self) -> dict[int, np.ndarray]:
        return {w.start + row: colors for w in self.workers if w.answers is not None
                for row, colors in w.answers.leds.items()}

    def take_rab_payloads(self) -> dict[int, np.ndarray]:
        return {w.start + row: payload for w in self.workers if w.answers is not None
                for row, payload in w.answers.rab.items()}

    def take_drone_commands(self) -> list:
        """Every worker's drone commands of the tick (each carries its robot: one order for all)."""
        return [command for w in self.workers if w.answers is not None for command in w.answers.drones]
