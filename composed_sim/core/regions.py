"""Regions of the arena stepped in parallel: one worker process per region, the state in shared memory.

ARGoS steps several physics engines, each owning a region of the arena, on its threads. Here a
region is a run of cells (core/cell_layout.py) and its engine a forked worker process that steps
them (core/cells.py's ``CellGroup``): Python's lock keeps threads from stepping pymunk in
parallel, processes do not share it.

Per tick the main process writes the wheel speeds into one anonymous shared mapping, sends each
worker a byte and waits for each one's byte back; a worker steps its cells from the state rows of
tick t (every robot's, for its ghosts) and writes its own robots' rows of tick t + 1 into the
other half of the mapping. The mapping has no name, so nothing is left behind however the run
ends; a worker ends when the main process closes its socket, when it dies (PR_SET_PDEATHSIG) or
when ``close`` kills it. The workers ignore Ctrl-C: the main process stops them. (Linux sends the
death signal when the *thread* that forked ends: build a Simulation with regions in a thread that
outlives it, as the hosts do.)

Robots move between regions at tick boundaries with their state: a robot near a border is
simulated on both sides (a ghost on one), so the cell that takes it over already holds it.
"""
from __future__ import annotations

import ctypes
import mmap
import os
import signal
import socket
import sys
import time
import traceback
import weakref
from typing import Optional, Sequence

import numpy as np

from composed_sim.core.cell_layout import CellLayout
from composed_sim.core.cells import STATE_FIELDS, CellGroup
from composed_sim.core.cell_engine import CellEngine
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import World

_STEP, _DONE, _FAILED, _QUIT = b"s", b"d", b"e", b"q"
_PR_SET_PDEATHSIG = 1
_CLOSE_WAIT_S = 5.0


class RegionError(RuntimeError):
    """A region's worker failed (its error, or its exit) or is gone."""


class RegionPhysics(CellEngine):
    """The cells of ``layout``, each region's in a worker process of its own."""

    def __init__(self, world: World, models: Sequence[RobotModel], positions: np.ndarray, headings: np.ndarray,
                 layout: CellLayout, groups: Optional[list[list[int]]] = None):
        """``groups``: the cells each process steps (default: each region's cells)."""
        super().__init__(models, positions, headings, layout)
        n = self.n
        # [2, n, 6] the state of the ticks t and t + 1 in turn, then [n, 2] the wheel speeds.
        self._memory = mmap.mmap(-1, max(1, (2 * n * STATE_FIELDS + 2 * n) * 8))
        words = np.frombuffer(self._memory, dtype=np.float64)
        self._states = words[:2 * n * STATE_FIELDS].reshape(2, n, STATE_FIELDS)
        self._wheels = words[2 * n * STATE_FIELDS:].reshape(n, 2)
        self._states[0] = self.initial_state(positions, headings)
        self._current = 0
        cells = layout.cell_region()
        if groups is None:
            groups = [np.flatnonzero(cells == region).tolist() for region in range(layout.n_regions)]
        self.pids: list[int] = []
        self._sockets: list[socket.socket] = []
        self._closer = weakref.finalize(self, _shut_down, self.pids, self._sockets)
        try:
            for mine in groups:
                self._fork(lambda mine=mine: CellGroup(world, models, layout, mine, self._states[0]))
            self._wait_all()       # each worker answers once its cells are built
        except BaseException:
            self.close()
            raise

    def _fork(self, build) -> None:
        # Packets keep the messages apart: a command or a reply is one recv.
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        pid = os.fork()
        if pid == 0:                                   # the worker: never returns
            code = 1
            try:
                ours.close()
                for s in self._sockets:
                    s.close()
                _worker(theirs, build, self._states, self._wheels)
                code = 0
            finally:
                os._exit(code)
        theirs.close()
        self.pids.append(pid)
        self._sockets.append(ours)

    def _wait_all(self) -> None:
        for region, s in enumerate(self._sockets):
            reply = _receive(s)
            if reply[:1] != _DONE:
                message = reply[1:].decode(errors="replace") if reply else "its process ended"
                raise RegionError(f"physics region {region}: {message}")

    def state(self) -> np.ndarray:
        return self._states[self._current]

    def step(self) -> None:
        if not self.pids:
            raise RegionError("the physics regions are closed")
        try:
            self._wheels[:, 0], self._wheels[:, 1] = self._left_mps, self._right_mps
            for s in self._sockets:
                s.sendall(_STEP + bytes([self._current]))
            self._wait_all()
        except BaseException:
            self.close()        # a tick half done cannot go on: no worker outlives it
            raise
        self._current = 1 - self._current

    def close(self) -> None:
        """End the workers (idempotent); the state stays readable."""
        self._states = self._states.copy()
        self._closer()


def _worker(sock: socket.socket, build, states: np.ndarray, wheels: np.ndarray) -> None:
    """A region's process: build its cells, then step them on each byte until the socket closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    try:
        group = build()
    except Exception:    # noqa: BLE001 - any failure goes back to the main process as its traceback
        sock.sendall(_FAILED + traceback.format_exc().encode())
        return
    sock.sendall(_DONE)
    while True:
        command = _receive(sock)
        if command[:1] != _STEP:
            return
        current = command[1]
        try:
            group.step(states[current], wheels[:, 0], wheels[:, 1], states[1 - current])
        except Exception:    # noqa: BLE001 - any failure goes back to the main process as its traceback
            sock.sendall(_FAILED + traceback.format_exc().encode())
            return
        sock.sendall(_DONE)


def _receive(sock: socket.socket) -> bytes:
    """One message (a command, or a reply with its error text); b"" once the other side is gone."""
    try:
        return sock.recv(1 << 16)
    except ConnectionResetError:
        return b""


def _shut_down(pids: list[int], sockets: list[socket.socket]) -> None:
    """Tell each worker to quit and close its socket, then wait for the workers, killing the late.
    (Closing alone is not enough: a worker forked later by another engine holds a copy of it.)"""
    for s in sockets:
        try:
            s.sendall(_QUIT)
        except OSError:
            pass             # that worker is gone already
        s.close()
    for pid in pids:
        _wait_or_kill(pid)
    pids.clear()
    sockets.clear()


def _wait_or_kill(pid: int) -> None:
    deadline = time.monotonic() + _CLOSE_WAIT_S
    try:
        while time.monotonic() < deadline:
            if os.waitpid(pid, os.WNOHANG)[0]:
                return
            time.sleep(0.005)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except ChildProcessError:
        pass                 # reaped already
