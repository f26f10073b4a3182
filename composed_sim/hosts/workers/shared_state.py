"""The world's state and the commands, shared between the main process and its workers.

Each tick the main process writes what the sensors read (every robot's pose, LEDs and
range-and-bearing payload: core/senses.py's SensingInputs) and every robot's wheels and odometry
into one shared-memory block, then wakes each worker with a small message; each worker reads its
block's sensors from it in place and writes its robots' commands back into it. Nothing of that
is pickled or copied through a socket. The lockstep order makes it safe without locks: the main
process writes only while every worker waits for the next tick, a worker writes only its own
rows, and the main process reads the commands only once every worker has answered.

The main process also builds the tick's neighbour index of the robots (a k-d tree) once and
shares it, pickled: every worker senses its block against the whole swarm and would otherwise
build the same tree again, K times a tick (docs/speed.md, "What a worker pays for the whole
swarm"). A tree that does not fit its room is left out, and each worker builds its own.

The block is an anonymous memory file (``memfd_create``) whose descriptor the workers inherit:
it has no name to leak, and goes away with the last process that maps it, a killed one included.
"""
from __future__ import annotations

import mmap
import os
import pickle
from typing import Optional

import numpy as np

from composed_sim.core.odometry import WheelReadings
from composed_sim.core.senses import RobotRows, SensingInputs, Senses
from composed_sim.devices.common.sensors import kd_tree

TREE_BYTES_PER_ROBOT = 64       # a pickled tree takes about 39 (scipy 1.x, 2-D points)


def _layout(n: int, leds: int, payload_bytes: int) -> list[tuple[str, tuple, np.dtype]]:
    f8, u1 = np.dtype(np.float64), np.dtype(np.uint8)
    return [("positions", (n, 2), f8), ("headings", (n,), f8), ("led_colors", (n, leds, 3), u1),
            ("rab_payloads", (n, payload_bytes), u1),
            ("wheel_velocities", (n, 2), f8), ("wheel_distances", (n, 2), f8), ("axis_lengths", (n,), f8),
            ("odometry", (n, 3), f8), ("odometry_twist", (n, 2), f8),
            ("linear", (n,), f8), ("angular", (n,), f8),           # the commands, written by the workers
            ("altitudes", (n,), f8),                               # [n] m: 0 on wheels (core/flight.py)
            ("supervisor_info", (n,), np.dtype(np.uint16)),        # [n] a drone's status bits (core/senses.py)
            ("tree_bytes", (1,), np.dtype(np.int64)), ("tree", (TREE_BYTES_PER_ROBOT * n + 4096,), u1)]


class SharedState:
    """Numpy views over one shared memory file: the main process makes it (``fd`` None) and
    passes ``fd`` on to the workers, which map the same file."""

    def __init__(self, senses: Senses, payload_bytes: int, fd: Optional[int] = None, share_tree: bool = True):
        """``share_tree``: ``write`` also builds the robots' tree for the workers (False where
        they are on other machines, which get the state without it)."""
        self.share_tree = share_tree
        layout = _layout(senses.n, senses.n_leds, payload_bytes)
        size = max(sum(int(np.prod(shape)) * dtype.itemsize for _, shape, dtype in layout), 1)
        if fd is None:
            fd = os.memfd_create("composed_sim_state", 0)     # not inherited but where passed on
            os.ftruncate(fd, size)
        self.fd = fd
        self._map = mmap.mmap(fd, size)
        self.views: dict[str, np.ndarray] = {}
        offset = 0
        for key, shape, dtype in layout:
            self.views[key] = np.ndarray(shape, dtype, buffer=self._map, offset=offset)
            offset += int(np.prod(shape)) * dtype.itemsize

    # --- the main process ---------------------------------------------------------------------

    def write(self, inputs: SensingInputs, rows: RobotRows) -> None:
        v = self.views
        v["positions"][:], v["headings"][:] = inputs.positions, inputs.headings
        v["led_colors"][:], v["rab_payloads"][:] = inputs.led_colors, inputs.rab_payloads
        v["wheel_velocities"][:], v["wheel_distances"][:] = rows.wheels.velocities_mps, rows.wheels.distances_m
        v["axis_lengths"][:] = rows.wheels.axis_length_m
        v["odometry"][:], v["odometry_twist"][:] = rows.odometry, rows.odometry_twist
        if inputs.altitudes is not None:
            v["altitudes"][:] = inputs.altitudes
        if inputs.supervisor_info is not None:
            v["supervisor_info"][:] = inputs.supervisor_info
        tree = pickle.dumps(kd_tree(inputs.positions), protocol=pickle.HIGHEST_PROTOCOL) if self.share_tree else b""
        fits = len(tree) <= len(v["tree"])
        if fits:
            v["tree"][:len(tree)] = np.frombuffer(tree, np.uint8)
        v["tree_bytes"][0] = len(tree) if fits else 0

    # --- a worker -------------------------------------------------------------------------------

    def inputs(self, tick: int, route_messages: bool, scene, floor, lights) -> SensingInputs:
        v = self.views
        size = int(v["tree_bytes"][0])
        tree = pickle.loads(memoryview(v["tree"][:size])) if size else None
        return SensingInputs(tick, v["positions"], v["headings"], v["led_colors"], v["rab_payloads"], scene,
                             floor, lights, route_messages, v["altitudes"], v["supervisor_info"], tree)

    def rows(self, block: slice) -> RobotRows:
        """The block's wheels and odometry, copied: its frame may outlive the tick."""
        v = self.views
        return RobotRows(WheelReadings(v["wheel_velocities"][block].copy(), v["wheel_distances"][block].copy(),
                                       v["axis_lengths"][block].copy()),
                         v["odometry"][block].copy(), v["odometry_twist"][block].copy())

    def write_commands(self, block: slice, linear: np.ndarray, angular: np.ndarray) -> None:
        self.views["linear"][block], self.views["angular"][block] = linear, angular

    def close(self) -> None:
        self.views = {}
        self._map.close()
        os.close(self.fd)
