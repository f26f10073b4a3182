"""Rounds of calls between places when the run's places are spread over processes: the one loop
and the one routing rule, whatever carries a round (worker pipes, a machine's Dask actor, the
multi-process mode's DDS links).

A call from a robot to a run-wide node (or back) may cross processes (hosting/calls/between_places.py).
It is answered within the tick, in the same order as in one process, by rounds that the main
process leads: once the processes handed calls are idle, the calls they made go to the
processes of their places, in the one order of the handover, and each runs until idle again;
when a round finds no call in flight anywhere, the phase is over. Two phases a tick: before the
sensors (what reached the robots at the tick's start: the run-wide nodes' calls from their part
of it) and after them.

A mode says how a round reaches its processes (``Rounds``'s four methods); with worker pipes
(``PipeRounds``), each worker sends its calls once idle (``("idle", calls)``), gets its share of
a round (``("calls", calls)``), and hears that the phase is over (``("go",)``). Only runs whose
nodes may call across places pay for them (``needed``: a worker said so when ready, or with a
tick's answers).
"""
from __future__ import annotations

import time
from multiprocessing.connection import wait as wait_for_connections
from typing import Callable, Collection, Container, Optional, Sequence

from composed_sim.hosting.calls.between_places import RUN_WIDE_ORIGIN, handover_order


def reached(destination: Optional[int], places: Sequence[Container[int]]) -> list[int]:
    """Which of ``places`` (each the robots one process holds, in robot order; the first holds
    the run-wide nodes too) a call for ``destination`` goes to: every one (None: what every
    process serves), the first (``RUN_WIDE_ORIGIN``: the run-wide nodes live with the first
    robots), or the one holding that robot. The one routing rule of the rounds."""
    if destination is None:
        return list(range(len(places)))
    if destination == RUN_WIDE_ORIGIN:
        return [0]
    return [k for k, robots in enumerate(places) if destination in robots][:1]


def routed(items: list, places: Sequence[Container[int]], live: Collection[int]) -> dict[int, list]:
    """Each live place's share of ``items`` (by its index in ``places``), in the handover's order."""
    shares: dict[int, list] = {k: [] for k in live}
    for item in handover_order(items):
        for k in reached(item.destination, places):
            if k in shares:
                shares[k].append(item)
    return shares


def worker_places(workers: list) -> tuple[list[range], list[int]]:
    """Workers' (hosts/workers/worker_host.Worker, in robot order) places for ``routed``, and the live ones."""
    return [range(w.start, w.stop) for w in workers], [k for k, w in enumerate(workers) if w.dead is None]


class Rounds:
    """The rounds of one phase of a tick, led from this process; a mode gives the four methods."""

    def places(self) -> tuple[Sequence[Container[int]], Collection[int]]:
        """The processes' places (``reached``), and those still live."""
        raise NotImplementedError

    def made(self) -> list:
        """Once every process handed a share of the last round (or, first, every one) is idle:
        the calls made since."""
        raise NotImplementedError

    def hand_over(self, shares: dict[int, list]) -> None:
        """A round's share to each process (by its index in ``places``)."""
        raise NotImplementedError

    def over(self) -> None:
        """No call is in flight anywhere: the phase is over."""

    def lead(self, calls: list) -> None:
        """Rounds until no call is in flight anywhere; ``calls``: those for the first one."""
        while True:
            calls = calls + self.made()
            if not calls:
                self.over()
                return
            self.hand_over(routed(calls, *self.places()))
            calls = []


class PipeRounds(Rounds):
    """The rounds over worker processes' pipes (the worker host; a machine's agent over its workers)."""

    def __init__(self, workers: list, patience_s: float, lost: Callable[[object, Optional[str]], None]):
        """``workers``: hosts/workers/worker_host.Worker, in robot order; ``lost(worker, reason)``: a worker
        that died or stopped answering."""
        self._workers, self._patience_s, self._lost = workers, patience_s, lost
        self.needed = False
        self.pending: list = []      # calls of the run-wide nodes' part of the next tick, for its first round

    def run(self) -> None:
        """One phase's rounds, the pending calls in the first."""
        calls, self.pending = self.pending, []
        self.lead(calls)

    def places(self) -> tuple[list[range], list[int]]:
        return worker_places(self._workers)

    def made(self) -> list:
        calls = []
        waiting = {w.conn: w for w in self._workers if w.dead is None}
        for _, (kind, made) in replies(waiting, self._patience_s, self._lost, "finishing a round of calls"):
            if kind != "idle":
                raise RuntimeError(f"a worker answered a round with {kind!r}, not 'idle'")
            calls += made
        return calls

    def hand_over(self, shares: dict[int, list]) -> None:
        send_to_live(self._workers, lambda k: ("calls", shares[k]), self._lost)

    def over(self) -> None:
        send_to_live(self._workers, lambda k: ("go",), self._lost)


def send_to_live(workers: list, message: Callable[[int], tuple], lost: Callable[[object, Optional[str]], None]) -> None:
    """``message(k)`` to each live worker (``k``: its index in ``workers``); one whose pipe is closed is lost."""
    for k, w in enumerate(workers):
        if w.dead is None:
            try:
                w.conn.send(message(k))
            except OSError:
                lost(w, None)


def replies(waiting: dict, patience_s: float, lost: Callable[[object, Optional[str]], None], what: str):
    """``(worker, message)`` as each worker of ``waiting`` (its connection → the worker) sends its
    next message, until every one has or ``patience_s`` passed: those still silent then are lost
    ("stopped answering … without ``what``"), as is one whose connection closed (it died)."""
    deadline = time.monotonic() + patience_s
    while waiting:
        left = deadline - time.monotonic()
        if left <= 0:
            for w in waiting.values():
                lost(w, f"worker process stopped answering ({patience_s:.0f} s without {what}), killed")
            return
        for conn in wait_for_connections(list(waiting), timeout=left):
            w = waiting.pop(conn)
            try:
                message = conn.recv()
            except (EOFError, OSError):
                lost(w, None)
                continue
            yield w, message
