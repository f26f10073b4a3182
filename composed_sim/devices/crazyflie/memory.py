"""Each drone's trajectory memory: uploaded polynomial pieces and the trajectories defined on them.

The firmware keeps 4 KiB of trajectory memory, which holds 31 pieces (a piece: 4 × 8 float
coefficients and a duration, 132 bytes), and a table of 31 trajectory definitions, each an offset
into that memory and a piece count. Uploading writes pieces at a piece offset (a write past the
end fails and writes nothing); defining names a run of them; several definitions may share or
overlap pieces, and a piece rewritten while a trajectory runs changes that trajectory from the
next evaluation on, as on the drone.
"""
from __future__ import annotations

import numpy as np

PIECE_SLOTS = 4096 // 132            # TRAJECTORY_MEMORY_SIZE / sizeof(struct poly4d) = 31
TRAJECTORY_IDS = 31                  # NUM_TRAJECTORY_DEFINITIONS
ENOEXEC = 8                          # the firmware's answer to a definition it cannot hold
MEMORY_FULL = 1                      # our code for a write past the end (the firmware's write returns false)


class TrajectoryMemory:
    """Pieces and definitions of ``n`` drones; the piece arrays are made on the first upload."""

    def __init__(self, n: int):
        self.n = n
        self.coefficients = np.zeros((0, PIECE_SLOTS, 4, 8))    # [n, 31, 4, 8] once written
        self.durations = np.zeros((0, PIECE_SLOTS))             # [n, 31]
        self.offset = np.zeros((n, TRAJECTORY_IDS), dtype=np.int64)
        self.n_pieces = np.zeros((n, TRAJECTORY_IDS), dtype=np.int64)
        self.defined = np.zeros((n, TRAJECTORY_IDS), dtype=bool)

    def _allocate(self) -> None:
        if len(self.coefficients) == 0:
            self.coefficients = np.zeros((self.n, PIECE_SLOTS, 4, 8))
            self.durations = np.zeros((self.n, PIECE_SLOTS))

    def write(self, drones: np.ndarray, offset: int, coefficients, durations) -> np.ndarray:
        """Pieces [p, 4, 8] with durations [p] (s) written at piece ``offset`` of every drone in
        ``drones`` → a code per drone: 0, or MEMORY_FULL where they do not fit (nothing written)."""
        coefficients = np.asarray(coefficients, dtype=np.float64).reshape(-1, 4, 8)
        durations = np.asarray(durations, dtype=np.float64).reshape(-1)
        if len(durations) != len(coefficients):
            raise ValueError(f"{len(coefficients)} pieces but {len(durations)} durations")
        drones = np.atleast_1d(drones)
        if offset < 0 or offset + len(durations) > PIECE_SLOTS:
            return np.full(len(drones), MEMORY_FULL, dtype=np.int64)
        self._allocate()
        span = slice(offset, offset + len(durations))
        self.coefficients[drones, span] = coefficients
        self.durations[drones, span] = durations
        return np.zeros(len(drones), dtype=np.int64)

    def define(self, drones: np.ndarray, trajectory_id: int, offset: int, n_pieces: int) -> np.ndarray:
        """Trajectory ``trajectory_id`` is ``n_pieces`` pieces from piece ``offset`` → a code per
        drone: 0, or ENOEXEC for an id the table does not have. Like the firmware it takes a run
        past the memory's end; unlike it (it would read past its memory) such a trajectory is
        never started (``is_defined``)."""
        drones = np.atleast_1d(drones)
        if not 0 <= trajectory_id < TRAJECTORY_IDS:
            return np.full(len(drones), ENOEXEC, dtype=np.int64)
        self._allocate()
        self.offset[drones, trajectory_id] = offset
        self.n_pieces[drones, trajectory_id] = n_pieces
        self.defined[drones, trajectory_id] = True
        return np.zeros(len(drones), dtype=np.int64)

    def is_defined(self, drones: np.ndarray, trajectory_id: int) -> np.ndarray:
        """[d] bool: the id is a defined trajectory of each drone, of at least one piece, within the
        memory (an id outside the table: False). The firmware would start the others and read
        past its memory; here they are ignored as undefined ones are."""
        if not 0 <= trajectory_id < TRAJECTORY_IDS:
            return np.zeros(len(np.atleast_1d(drones)), dtype=bool)
        count = self.n_pieces[drones, trajectory_id]
        inside = (count >= 1) & (self.offset[drones, trajectory_id] + count <= PIECE_SLOTS)
        return self.defined[drones, trajectory_id] & inside

    def total_duration(self, drones: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
        """[d] the summed durations of each drone's run of pieces (piecewise_duration before timescale)."""
        if len(self.durations) == 0:
            return np.zeros(len(drones))
        slots = np.arange(PIECE_SLOTS)
        inside = (slots >= first[:, None]) & (slots < (first + count)[:, None])
        return np.where(inside, self.durations[drones], 0.0).sum(axis=1)
