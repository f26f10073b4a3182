"""The answers to a tick, robot by robot, and what becomes of a robot that does not answer: the
simulator node's bookkeeping (ros/simulator_node.py), with no ROS in it.

Answers arrive through executor callbacks, possibly on worker threads; the host waits on
``wait_for_answers``. Everything here is guarded by ``lock``, re-entrant: a violation recorded
under it may fail its robot (max_violations).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable, Collection, Optional, Sequence

import numpy as np

from composed_sim.core.violations import FAILED, Violation
from composed_sim.world.schema import Lockstep


class AnswerLedger:
    def __init__(self, names: list[str], rows: np.ndarray, lockstep: Optional[Lockstep],
                 answers_every_ticks: Optional[Sequence[int]], answers_when_published: Optional[Sequence[bool]],
                 answers_by_firmware: Optional[Sequence[bool]] = None):
        """``rows``: the robots' rows in the simulation's arrays. ``lockstep``: the world's fault
        policy; None: robots are never failed for being unresponsive or for their violations.
        ``answers_every_ticks``: per robot, k: it answers ticks 0, k, 2k … and keeps its last
        command in between (None: every tick). ``answers_when_published``: per robot, whether a
        tick its nodes leave without a cmd_vel keeps its last command, without a violation
        (``settle_idle``; None: no robot). ``answers_by_firmware``: per robot, whether its firmware
        answers its ticks (a drone: core/flight.py): settled as each tick opens, never waited for
        (None: no robot)."""
        n = len(names)
        self._names = names
        self._index = {name: i for i, name in enumerate(names)}
        self.rows = rows
        self._unresponsive_s = math.inf if lockstep is None else lockstep.unresponsive_s
        self._max_violations = None if lockstep is None else lockstep.max_violations
        self._every = None if answers_every_ticks is None or all(k == 1 for k in answers_every_ticks) \
            else np.asarray(answers_every_ticks)
        self.when_published = np.zeros(n, dtype=bool) if answers_when_published is None \
            else np.asarray(answers_when_published, dtype=bool)
        # Robots whose nodes will publish cmd_vel later (``answer_later``): quiet until their first
        # answer, then as the world file says (``_as_said``).
        self._as_said = self.when_published.copy()
        self.later = np.zeros(n, dtype=bool)
        self.by_firmware = np.zeros(n, dtype=bool) if answers_by_firmware is None \
            else np.asarray(answers_by_firmware, dtype=bool)
        self._later_until = np.full(n, math.inf)          # the tick at which ``later`` ends at the latest
        self.linear = np.zeros(n)       # [n] m/s
        self.angular = np.zeros(n)      # [n] rad/s
        self.answered = np.zeros(n, dtype=bool)  # the robot's part of this tick is settled
        self.rejected = np.zeros(n, dtype=bool)  # … by a violation: it gets the fallback
        self.failed = np.zeros(n, dtype=bool)    # stopped for good: not waited for, zero command
        self.on_failed: list[Callable[[str], None]] = []   # hosts stop what is left of a failed controller
        self._violation_counts = np.zeros(n, dtype=int)
        self._last_accepted_s = np.full(n, math.inf)     # monotonic time of each robot's last good answer
        self.lock = threading.RLock()
        self._all_answered = threading.Event()
        self._n_answered = 0
        self._n_expected = n
        self.current_key = -1           # stamp (ns) answers must carry; -1 once the window closed
        self.tick_key = 0               # stamp (ns) of the last published tick
        self.opened_ns: Optional[int] = None    # wall time the tick's sensors went out
        self.current_tick = -1
        self.violations: list[Violation] = []

    # --- a tick's window ------------------------------------------------------------------------

    def open_tick(self, tick: int, key: int) -> None:
        """Tick ``tick``, stamped ``key`` ns, is being published: its answer window opens."""
        with self.lock:
            if self.later.any():
                due = self.later & (self._later_until <= tick)
                self.later[due], self.when_published[due] = False, self._as_said[due]
            # Robots answering every k-th tick are settled, keeping their last command, in between.
            self.answered[:] = False if self._every is None else tick % self._every != 0
            self.answered |= self.by_firmware
            self.rejected[:] = False
            self._n_answered = 0
            self._n_expected = int(np.count_nonzero(~self.failed & ~self.answered))
            if self._n_expected == 0:
                self._all_answered.set()
            else:
                self._all_answered.clear()
            self.current_key = self.tick_key = key
            self.current_tick = tick
            # Wall time the sensors went out (DDS source timestamps use it); nothing precedes tick 0.
            self.opened_ns = time.time_ns() if tick > 0 else None
            if tick == 0:   # unresponsiveness counts from the first tick on
                self._last_accepted_s[:] = time.monotonic()

    def accepts(self, i: int, key: int, tick_ns: int) -> bool:
        """Called with the lock held: does robot i's answer stamped ``key`` settle its part of the
        open tick? An answer to an earlier tick comes from a robot whose miss of that tick is
        recorded already; any other stamp is a contract violation of its own. A later answer to
        the open tick replaces the one before (a robot's base acts on the last command it got: a
        callback that publishes a stop, then the next command, answers with the next); one to a
        tick already rejected does not count."""
        if self.failed[i]:
            return False
        if key != self.current_key:
            if not (key <= self.tick_key and key % tick_ns == 0):
                self.record(self.current_tick, i, f"answer stamped {key} ns answers no tick "
                            f"published so far (the last is {self.tick_key} ns)")
            return False
        return not self.rejected[i]

    def answer_later(self, robots: Collection[str], until_tick: Optional[int] = None) -> None:
        """``robots``' nodes cannot answer yet: no active cmd_vel publisher (a lifecycle node not
        yet active, a publisher made in a callback), or (``until_tick``) the first period of their
        timers, or of the run-wide nodes' timers, has not passed. Each keeps its last command,
        without a violation, until its first answer (or that tick), as a robot's base does; from
        then on it answers as its world file says. A robot said so twice waits for the later."""
        until = math.inf if until_tick is None else until_tick
        with self.lock:
            for robot in robots:
                i = self._index[robot]
                self._later_until[i] = max(self._later_until[i], until) if self.later[i] else until
                self.later[i] = self.when_published[i] = True

    def hold(self, i: int, linear: float, angular: float) -> None:
        """Called with the lock held, for an answer to no open tick (it came after its tick
        closed): a robot that answers when published keeps it as its command from the next tick
        on, as a robot's base keeps the last command it got; any other robot's is dropped (its
        miss of that tick is recorded). Processes outside the run publish when they please
        (hosts/outside_controllers.py)."""
        if self.when_published[i] and not self.failed[i] and math.isfinite(linear) and math.isfinite(angular):
            self.linear[i], self.angular[i] = linear, angular

    def take(self, i: int, linear: float, angular: float) -> None:
        """Called with the lock held, for an answer ``accepts`` took: a finite command is robot
        i's, else the answer is a violation."""
        if self.later[i]:
            self.later[i], self.when_published[i] = False, self._as_said[i]
        if not (math.isfinite(linear) and math.isfinite(angular)):
            self.rejected[i] = True
            self.record(self.current_tick, i, f"non-finite velocity command rejected "
                        f"(linear {linear}, angular {angular})")
        else:
            self.linear[i] = linear
            self.angular[i] = angular
            self._last_accepted_s[i] = time.monotonic()
        self._settle(i)

    def close_tick(self, fallback: str, previous: tuple[np.ndarray, np.ndarray],
                   commands: tuple[np.ndarray, np.ndarray]) -> None:
        """End the answer window and write the robots' commands into ``commands`` (linear [N],
        angular [N], indexed by simulation row). Robots that did not answer get the fallback
        (zero, or ``previous``), recorded as a violation unless already failed."""
        with self.lock:
            self.current_key = -1   # later answers to this tick are stale
            tick = self.current_tick
            for i in np.flatnonzero(~self.answered & ~self.failed):
                self.record(tick, i, "no answer before the watchdog")
            good = self.answered & ~self.rejected & ~self.failed
            now = time.monotonic()
            for i in np.flatnonzero(~good & (now - self._last_accepted_s >= self._unresponsive_s)):
                self._fail(i, f"unresponsive: no accepted answer for {now - self._last_accepted_s[i]:.1f} s")
            linear, angular = self.linear.copy(), self.angular.copy()
            stopped = self.failed.copy()
        bad = ~good & ~stopped
        if fallback == "previous":
            linear[bad], angular[bad] = previous[0][self.rows[bad]], previous[1][self.rows[bad]]
        else:
            linear[bad], angular[bad] = 0.0, 0.0
        linear[stopped], angular[stopped] = 0.0, 0.0
        commands[0][self.rows] = linear
        commands[1][self.rows] = angular

    def wait_for_answers(self, timeout_s: float) -> bool:
        return self._all_answered.wait(timeout_s)

    @property
    def all_answered(self) -> bool:
        return self._all_answered.is_set()

    @property
    def answered_count(self) -> int:
        return self._n_answered

    # --- settling a robot's part otherwise -----------------------------------------------------

    def mark_failed(self, robot: str, reason: str) -> None:
        """Stop a robot for good (its controller is gone, hung or past max_violations): recorded
        once, then stopped (zero command) every tick, never waited for."""
        with self.lock:
            self._fail(self._index[robot], reason)

    def reject_answer(self, robot: str, reason: str) -> None:
        """Settle a robot's part of the open tick as a violation: it gets the fallback, whatever
        it answered or will answer to this tick (e.g. its callback overran the watchdog)."""
        i = self._index[robot]
        with self.lock:
            if self.current_key < 0 or self.failed[i]:
                return
            self.rejected[i] = True
            self._settle(i)
            self.record(self.current_tick, i, reason)

    def settle_idle(self, robots: Optional[Collection[str]] = None) -> int:
        """The robots that answer when published (``answers: when_published``) and have not
        answered the open tick, whose nodes have nothing left to do in it (all of them, or
        ``robots``): settled, keeping their last command. How many were settled."""
        with self.lock:
            if self.current_key < 0:
                return 0
            rows = np.flatnonzero(self.when_published & ~self.answered & ~self.failed) if robots is None \
                else [i for i in (self._index[r] for r in robots)
                      if self.when_published[i] and not self.answered[i] and not self.failed[i]]
            for i in rows:
                self._settle(i)
                self._last_accepted_s[i] = time.monotonic()     # quiet by design, not unresponsive
            return len(rows)

    def record(self, tick: int, i: int, reason: str, counts: bool = True) -> None:
        """Called with the lock held. ``counts``: towards the robot's max_violations."""
        self.violations.append(Violation(tick, self._names[i], reason))
        if not counts:
            return
        self._violation_counts[i] += 1
        if self._max_violations is not None and self._violation_counts[i] >= self._max_violations:
            self._fail(i, f"stopped after {self._violation_counts[i]} violations (max_violations)")

    def _settle(self, i: int) -> None:
        # A robot failed while its answer was handled (its last violation) is no longer expected
        # (_fail took it out of the count): settling it too would close the tick one answer early.
        if not self.answered[i] and not self.failed[i]:
            self.answered[i] = True
            self._n_answered += 1
            if self._n_answered >= self._n_expected:
                self._all_answered.set()

    def _fail(self, i: int, reason: str) -> None:
        if self.failed[i]:
            return
        self.failed[i] = True
        self.record(self.current_tick, i, FAILED + reason)
        if not self.answered[i]:
            self._n_expected -= 1
            if self._n_answered >= self._n_expected:
                self._all_answered.set()
        for hook in self.on_failed:
            hook(self._names[i])
