"""Running a block's callbacks while a tick is open, until every robot answered (a part of
``ParticipantGroups``, hosting/participant_groups.py): from the calling thread (the lockstep
executor, and the stock ones the callback guard must be able to interrupt), or waiting for a
multi-threaded executor's threads; robots that answer when published settled once idle; then the
rounds of calls between places until none is in flight (hosting/calls/between_places.py).
"""
from __future__ import annotations

import time
from typing import Optional

from composed_sim.hosting.executors.running import SETTLE_ROUNDS, driven_by_caller, is_idle, run_until_idle

WAIT_SLICE_S = 0.02           # how long one spin_once may wait for a callback while a tick is open
QUIET_CHECK_S = 0.002         # multi-threaded executor: how often to look whether its threads are idle


class TickServing:
    def start_serving(self):
        """Before the first tick: returns ``wait_for_answers(timeout_s) -> bool`` for the tick
        loop, and a context manager to run the ticks in (it interrupts hung callbacks)."""
        if driven_by_caller(self.hosting.executor, guarded=True):
            wait = self._spin_until_answered
        else:
            # Its callbacks run on its worker threads; the tick loop waits for the simulator
            # nodes' "all answered".
            self.spinning.start_thread()
            wait = self._await_answers
        return wait, self.guard.interrupting_hangs(self.spinning.thread is None)

    def _await_answers(self, timeout_s: float) -> bool:
        """The multi-threaded executor's callbacks run on its threads: wait for every answer, then
        (when the tick's work may go on after an answer) for its threads to fall quiet."""
        deadline = time.monotonic() + timeout_s
        while self._quiet_robots and self.exchange.waiting_on_quiet_robots and time.monotonic() < deadline:
            calls = self._threads_quiet()
            if calls is None:
                self.exchange.wait_for_answers(QUIET_CHECK_S)
                continue
            # Only the robots whose callbacks had run by the quiet look, and only if no callback
            # started since: one that did may publish its answer after the take below (a thread
            # descheduled for milliseconds under load makes that window wide).
            ran = self._ran_since_open()
            self._take_ready_answers()
            if self.guard.calls == calls:
                self.exchange.settle_idle(ran)
        self._rounds_with_threads(deadline)
        answered = self.exchange.wait_for_answers(max(0.0, deadline - time.monotonic()))
        if answered and (self._settle or self.calls.in_flight):
            self._threads_quiet()
            while self._hand_over():
                self._threads_quiet()
        return answered

    def _rounds_with_threads(self, deadline: float) -> None:
        """The rounds of calls between places (hosting/calls/between_places.py), each once the
        executor's threads are quiet. In one process: while a call is in flight or may yet be made
        (the threads may not have reached the robots' sensors at the first look), until every robot
        answered. In a worker: the rounds the main process leads, until it says no call is in
        flight anywhere (hosting/calls/rounds.py); a call made after that is handed over as the
        next tick opens."""
        local = self.remote is None
        if not local:
            self._until_threads_reach_every_robot(deadline)
        while time.monotonic() < deadline:
            if local and (not self.calls_leave or self.exchange.all_answered):
                return
            if (self.calls.in_flight or not local) and self._threads_quiet() is not None:
                if not self._hand_over() and not local:
                    return
            self.exchange.wait_for_answers(QUIET_CHECK_S)

    def _until_threads_reach_every_robot(self, deadline: float) -> None:
        """In a worker the main process ends a phase's rounds once one finds no call anywhere, and
        the executor's threads may not have reached this block's robots' sensors at the first
        look (a call made after it waited for the next tick: no answer before the watchdog). So
        the first round waits until every robot here ran a callback in this tick, or all answered
        (``_ran_since_open`` names robots of this block only: counting them is enough)."""
        robots = self.stop - self.start
        while time.monotonic() < deadline and not self.exchange.all_answered and len(self._ran_since_open()) < robots:
            self.exchange.wait_for_answers(QUIET_CHECK_S)

    def _take_ready_answers(self) -> None:
        """Before robots are settled as idle: the callbacks are done and have published, but their
        answers may still wait to be taken (by an executor's threads, or an events queue): taken
        here first, so that only the robots that did not answer keep their command."""
        for node in self.simulator_nodes:
            node.take_ready_answers()

    def _ran_since_open(self) -> set[str]:
        """The robots that ran a callback since the tick opened: only those have had their tick's
        readings; an idle executor that has not reached a robot yet says nothing about it."""
        calls_of = dict(self.guard.calls_of)     # a copy: the executor's threads add robots to it
        # … and those with no cmd_vel publisher yet (a lifecycle node not active has no callback
        # to run): their nodes are done with the tick too.
        ran = {r for r, calls in calls_of.items() if calls > self._calls_at_open.get(r, 0)}
        return ran | set(self.answers_later)

    def _threads_quiet(self) -> Optional[int]:
        """Wait until no callback runs and none started since the last look, twice in a row (a
        message queued by the last callback is picked up within that time): the count of
        callbacks run by then, every one of them ended; None if that takes more than
        SETTLE_ROUNDS looks."""
        quiet, calls = 0, -1
        for _ in range(SETTLE_ROUNDS):
            # running before calls: a callback starting between the two reads shows in calls
            quiet = quiet + 1 if self.guard.running == 0 and self.guard.calls == calls else 0
            if quiet >= 2:
                return calls
            calls = self.guard.calls
            time.sleep(QUIET_CHECK_S)
        return None

    def _spin_until_answered(self, timeout_s: float) -> bool:
        """Executors driven from this thread (``executors.running.driven_by_caller``).

        Past the watchdog, the callbacks already queued still run before the tick closes: in one
        thread a late callback delays the ones behind it, and its lateness is its own (the guard
        rejects its answer), not theirs. Then the rounds of calls between places, until none is
        in flight (the tick's work may go on after the answers)."""
        answered = self._spin_until_answers(timeout_s)
        for _ in range(SETTLE_ROUNDS):
            if self._settle or self.block.directory.in_use:
                run_until_idle(self.executor, self._callbacks_run)
            if not self._hand_over():
                break
        return answered

    def _spin_until_answers(self, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        drain_left = 4 * len(self.controllers) + 16     # bounded: a busy timer cannot keep the tick open
        idle = 0
        while not self.exchange.all_answered:
            if self._quiet_robots and self.exchange.waiting_on_quiet_robots and time.monotonic() < deadline:
                if not is_idle(self.executor, self._callbacks_run):
                    continue            # it ran callbacks: look again
                self._take_ready_answers()
                if self.exchange.settle_idle(self._ran_since_open()):
                    continue
            if (self.calls.in_flight or self.remote is not None) and is_idle(self.executor, self._callbacks_run):
                # Every robot here is idle: the round's calls go to their places.
                if self._hand_over():
                    continue
                if self.remote is not None:     # quiet everywhere: no answer will come in this tick
                    return False
            if time.monotonic() < deadline:
                # A constant timeout: a stock executor keeps the ready callbacks of one wait only
                # while spin_once's arguments stay the same, and rebuilds its wait set over every
                # entity otherwise (with a changing timeout: once per callback; docs/speed.md, "The
                # stock executors"). The deadline is then met to within one slice.
                self.executor.spin_once(timeout_sec=WAIT_SLICE_S)
                continue
            before = (self.guard.calls, self.exchange.answered_count)
            self.executor.spin_once(timeout_sec=0)
            drain_left -= 1
            # Twice: a stock executor's spin_once may come back empty once, to rebuild its wait set.
            idle = idle + 1 if (self.guard.calls, self.exchange.answered_count) == before else 0
            if drain_left <= 0 or idle >= 2:
                return False
        return True

    def _callbacks_run(self) -> int:
        return self.guard.calls

