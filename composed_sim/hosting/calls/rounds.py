"""Rounds of calls between places when the robots are spread over worker processes.

A call from a robot to a run-wide node (or back) may cross workers (hosting/calls/between_places.py).
It is answered within the tick, in the same order as in one process, by rounds that the main
process leads: each worker runs until its nodes are idle and sends the calls they made
(``("idle", calls)``); once every worker has, the calls go to the workers of their places, in the
one order of the handover (``("calls", calls)``), and each runs until idle again; when a round
finds no call in flight anywhere, the main process says so (``("go",)``) and the phase is over.
Two phases a tick: before the sensors (what reached the robots at the tick's start: the
run-wide nodes' calls from their part of it) and after them. Only runs whose nodes may call
across places pay for them (``needed``: a worker said so when ready, or with a tick's answers).
"""
from __future__ import annotations

import time
from multiprocessing.connection import wait as wait_for_connections
from typing import Callable, Optional

from composed_sim.hosting.calls.between_places import blocks_reached, handover_order


class CallRounds:
    def __init__(self, workers: list, patience_s: float, lost: Callable[[object, Optional[str]], None]):
        """``workers``: hosts/workers/worker_host.Worker, in robot order; ``lost(worker, reason)``: a worker
        that died or stopped answering."""
        self._workers, self._patience_s, self._lost = workers, patience_s, lost
        self.needed = False
        self.pending: list = []      # calls of the run-wide nodes' part of the next tick, for its first round

    def run(self) -> None:
        """One phase's rounds, until no call is in flight anywhere."""
        calls, self.pending = self.pending, []
        while True:
            calls += self._collect_idle()
            live = [w for w in self._workers if w.dead is None]
            if not calls:
                self._send(live, lambda w: ("go",))
                return
            shares = routed(handover_order(calls), self._workers)
            self._send(live, lambda w: ("calls", shares[w.index]))    # noqa: B023 - sent within this round
            calls = []

    def _collect_idle(self) -> list:
        calls = []
        waiting = {w.conn: w for w in self._workers if w.dead is None}
        for _, (kind, made) in replies(waiting, self._patience_s, self._lost, "finishing a round of calls"):
            if kind != "idle":
                raise RuntimeError(f"a worker answered a round with {kind!r}, not 'idle'")
            calls += made
        return calls

    def _send(self, workers: list, message: Callable) -> None:
        for w in workers:
            try:
                w.conn.send(message(w))
            except OSError:
                self._lost(w, None)


def routed(items: list, workers: list) -> dict[int, list]:
    """Each live worker's share of ``items`` (by its index), in their order: what the one routing
    rule (``blocks_reached``) sends to its block of robots."""
    blocks = [(w.start, w.stop) for w in workers]
    shares: dict[int, list] = {w.index: [] for w in workers if w.dead is None}
    for item in items:
        for k in blocks_reached(item.destination, blocks):
            if workers[k].dead is None:
                shares[workers[k].index].append(item)
    return shares


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
