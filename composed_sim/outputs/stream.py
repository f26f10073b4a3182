"""A run's per-tick results streamed to disk as the run goes, so that memory does not grow with
the ticks (``composed-sim run --out DIR``).

While a run goes, and after it was killed outright, its trajectories are in ``DIR/trajectories/``:
one ``.npy`` file per array of ``trajectories.npz`` (``positions.npy`` [T+1, n, 2],
``headings.npy`` [T+1, n], ``led_colors.npy`` [T+1, n, 3], ``names.npy``, ``tick_s.npy``). Each
tick's rows are appended to the files as the tick ends; at every checkpoint (hosts/tick_loop.py,
every 100 ticks) the files are flushed and their headers rewritten to say how many rows are whole,
so ``numpy.load(path, mmap_mode="r")`` reads every file, during the run and after a SIGKILL, up to
the last checkpoint (the bytes after it are not part of the array). When the run ends (also
stopped by Ctrl-C or an error), the folder is packed into ``trajectories.npz`` piece by piece and
removed: a finished run's directory looks as it always did. ``metrics.csv`` and ``violations.csv``
grow the same way: rows appended at each checkpoint, never rewritten (unless the loop functions
bring a new column, which rewrites ``metrics.csv`` once with the wider header).

Memory per run: a buffer of 1 MB per array file, the metrics' first and last rows; nothing per
tick. The price: the packing at the end copies the trajectories once
(docs/speed.md, "Memory", gives what it costs).
"""
from __future__ import annotations

import csv
import io
import os
import shutil
import struct
import zipfile
from pathlib import Path
from typing import Iterable, Optional

import numpy as np

from composed_sim.hosts.tick_loop import Trajectories
from composed_sim.world.robot_models import display_colors

FOLDER = "trajectories"            # DIR/trajectories/: the arrays of a run that goes (or was killed)
ARRAYS = ("positions", "headings", "led_colors")
HEADER_BYTES = 128                 # a .npy header of fixed size, rewritten in place as rows are added
BUFFER_BYTES = 1 << 20             # per file: what is written between two system calls
COPY_BYTES = 16 << 20              # a piece of the packing into trajectories.npz


def _npy_header(dtype: np.dtype, shape: tuple) -> bytes:
    """A version 1.0 .npy header of exactly HEADER_BYTES (numpy's own pads to 64 bytes, so its
    length could change as the row count grows)."""
    text = repr({"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
                 "shape": tuple(shape)}).encode("latin1")
    room = HEADER_BYTES - 10 - 1 - len(text)
    if room < 0:
        raise ValueError(f"shape {shape} does not fit a {HEADER_BYTES}-byte .npy header")
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", HEADER_BYTES - 10) + text + b" " * room + b"\n"


class GrowingArray:
    """A .npy file that grows along its first axis: rows are appended, ``flush`` makes them
    part of the array on disk (its header's row count)."""

    def __init__(self, path: Path, dtype, row_shape: tuple):
        self.path, self.dtype, self.row_shape = Path(path), np.dtype(dtype), tuple(row_shape)
        self.rows = 0               # rows written
        self.rows_on_disk = 0       # rows the header counts
        self._file = open(self.path, "w+b", buffering=BUFFER_BYTES)
        self._file.write(_npy_header(self.dtype, (0, *self.row_shape)))
        self._file.flush()          # an empty array on disk from the start

    def append(self, row: np.ndarray) -> None:
        row = np.ascontiguousarray(row, dtype=self.dtype)
        if row.shape != self.row_shape:
            raise ValueError(f"{self.path.name}: a row of shape {row.shape}, expected {self.row_shape}")
        try:
            self._file.write(row.data)
        except OSError as e:        # a full disk: name the file
            raise OSError(e.errno, e.strerror, str(self.path)) from None
        self.rows += 1

    def flush(self) -> None:
        """The rows written so far become the array on disk: data first, then the header that
        counts them (a kill between the two leaves the previous count, with whole rows)."""
        if self._file.closed or self.rows == self.rows_on_disk:
            return
        try:
            self._file.flush()
            os.pwrite(self._file.fileno(), _npy_header(self.dtype, (self.rows, *self.row_shape)), 0)
        except OSError as e:
            raise OSError(e.errno, e.strerror, str(self.path)) from None
        self.rows_on_disk = self.rows

    def close(self) -> None:
        if not self._file.closed:
            self.flush()
            self._file.close()


class TrajectoryStream(Trajectories):
    """``hosts/tick_loop.Trajectories`` whose rows go to ``DIR/trajectories/`` as they are
    recorded; ``positions``, ``headings`` and ``led_colors`` read the flushed files back
    (memory-mapped). ``metrics_sink`` appends the loop functions' rows to ``DIR/metrics.csv``."""

    def __init__(self, out_dir: Path, names: list[str], tick_s: float, flies: bool = False):
        self.out_dir = Path(out_dir)
        self.folder = self.out_dir / FOLDER
        remove_results_of_before(self.out_dir)
        self.folder.mkdir(parents=True)
        n = len(names)
        np.save(self.folder / "names.npy", np.asarray(names))
        np.save(self.folder / "tick_s.npy", np.asarray(tick_s))
        self._arrays = {"positions": GrowingArray(self.folder / "positions.npy", np.float64, (n, 2)),
                        "headings": GrowingArray(self.folder / "headings.npy", np.float64, (n,)),
                        "led_colors": GrowingArray(self.folder / "led_colors.npy", np.uint8, (n, 3))}
        if flies:               # a world with drones: their heights (core/flight.py)
            self._arrays["altitudes"] = GrowingArray(self.folder / "altitudes.npy", np.float64, (n,))
        self.names, self.ticks_done = list(names), 0
        self.metrics = RowsFile(self.out_dir / "metrics.csv")
        self.violations = RowsFile(self.out_dir / "violations.csv", ["tick", "robot", "reason"])
        self._violations_written = 0
        self.metrics_sink = self.metrics.add

    @classmethod
    def factory(cls, out_dir: Path, tick_s: float):
        """What ``Host.run(trajectories=...)`` takes: the stream of a run writing into ``out_dir``."""
        def start(sim, ticks: int) -> "TrajectoryStream":
            stream = cls(out_dir, sim.names, tick_s, flies=sim.drones is not None)
            stream._append(sim)
            return stream
        return start

    def record(self, sim) -> None:
        self.ticks_done += 1
        self._append(sim)

    def _append(self, sim) -> None:
        arrays = self._arrays
        arrays["positions"].append(sim.positions)
        arrays["headings"].append(sim.headings)
        arrays["led_colors"].append(display_colors(sim.led_colors))
        if "altitudes" in arrays:
            arrays["altitudes"].append(sim.altitudes)

    def filled(self) -> "TrajectoryStream":
        return self

    def write_violations(self, violations: list) -> None:
        """Append the violations after those written before (the exchange keeps the whole list)."""
        new = violations[self._violations_written:]
        self.violations.add_many({"tick": v.tick, "robot": v.robot, "reason": v.reason} for v in new)
        self._violations_written += len(new)

    def flush(self) -> None:
        """Everything recorded so far on disk: the arrays' rows, the metrics and violations."""
        for array in self._arrays.values():
            array.flush()
        self.metrics.flush()
        self.violations.flush()

    def _read(self, name: str) -> np.ndarray:
        self._arrays[name].flush()
        return _mapped(self.folder / f"{name}.npy")[:self.ticks_done + 1]

    positions = property(lambda self: self._read("positions"))
    headings = property(lambda self: self._read("headings"))
    led_colors = property(lambda self: self._read("led_colors"))
    altitudes = property(lambda self: self._read("altitudes") if "altitudes" in self._arrays else None)

    def close(self) -> None:
        """Everything on disk, the array files closed (before packing them)."""
        self.flush()
        for array in self._arrays.values():
            array.close()


def pack_folder(folder: Path, f) -> None:
    """``trajectories.npz`` from a stream folder, in pieces (memory does not grow with the file):
    the floats stored, the rest deflated, as results._save_npz does."""
    with zipfile.ZipFile(f, "w", allowZip64=True) as z:
        for name in ("positions", "headings", "names", "tick_s", "led_colors", "altitudes"):
            path = folder / f"{name}.npy"
            if not path.exists():
                continue
            array = np.load(path, mmap_mode="r")
            info = zipfile.ZipInfo(f"{name}.npy")
            info.compress_type = zipfile.ZIP_STORED if array.dtype.kind in "fc" else zipfile.ZIP_DEFLATED
            with z.open(info, "w", force_zip64=True) as member:
                _copy_npy(path, array, member)
            del array


def _copy_npy(path: Path, array: np.ndarray, member) -> None:
    """The .npy file at ``path`` as numpy writes it, its whole rows only (a killed run's file
    may hold part of a row after its header's count)."""
    np.lib.format.write_array_header_1_0(member, np.lib.format.header_data_from_array_1_0(array))
    left = array.nbytes
    with open(path, "rb") as src:
        src.seek(array.offset)
        while left:
            piece = src.read(min(COPY_BYTES, left))
            if not piece:
                raise OSError(f"{path}: shorter than its header says")
            member.write(piece)
            left -= len(piece)


class RowsFile:
    """A CSV file that grows by rows: kept in memory until ``flush``, then appended in one write
    (a kill leaves whole rows). The header is the columns in the order they were first seen; a
    row with a new column rewrites the file once with the wider header."""

    def __init__(self, path: Path, columns: Optional[list[str]] = None):
        self.path, self.columns = Path(path), list(columns or [])
        self._pending: list[dict] = []
        self.first: Optional[dict] = None
        self.last: Optional[dict] = None
        self._started = False
        self.path.unlink(missing_ok=True)
        if self.columns:
            self._write_header()

    def add(self, row: dict) -> None:
        if self.first is None:
            self.first = row
        self.last = row
        self._pending.append(row)

    def add_many(self, rows: Iterable[dict]) -> None:
        for row in rows:
            self.add(row)

    def flush(self) -> None:
        if not self._pending:
            return
        new = [k for row in self._pending for k in row if k not in self.columns]
        if new:
            self.columns += list(dict.fromkeys(new))
            self._rewrite_with_new_columns()
        text = io.StringIO()
        csv.DictWriter(text, self.columns).writerows(self._pending)
        self._pending = []
        with open(self.path, "ab") as f:
            f.write(text.getvalue().encode())       # one write: a kill leaves whole rows

    def _write_header(self) -> None:
        text = io.StringIO()
        csv.writer(text).writerow(self.columns)
        self.path.write_bytes(text.getvalue().encode())
        self._started = True

    def _rewrite_with_new_columns(self) -> None:
        """The rows on disk again under the wider header (missing cells empty), replacing the file."""
        if not self._started:
            self._write_header()
            return
        part = self.path.with_name(self.path.name + ".part")
        with open(self.path, newline="") as src, open(part, "w", newline="") as dst:
            w = csv.DictWriter(dst, self.columns)
            w.writeheader()
            w.writerows(csv.DictReader(src))
        os.replace(part, self.path)


def remove_results_of_before(out_dir: Path) -> None:
    """A run into an ``--out`` used before starts without the trajectories of the run before."""
    (Path(out_dir) / "trajectories.npz").unlink(missing_ok=True)
    shutil.rmtree(Path(out_dir) / FOLDER, ignore_errors=True)


def load_folder(folder: Path) -> Trajectories:
    """The trajectories in a stream folder (a run that goes, or was killed): the rows its last
    checkpoint counted, memory-mapped; the arrays cut to the rows all of them hold."""
    folder = Path(folder)
    arrays = {name: _mapped(folder / f"{name}.npy") for name in ARRAYS}
    rows = min(len(a) for a in arrays.values())
    if (folder / "altitudes.npy").exists():
        altitudes = _mapped(folder / "altitudes.npy")
        rows = min(rows, len(altitudes))
    names = list(np.load(folder / "names.npy"))
    return Trajectories(names, arrays["positions"][:rows], arrays["headings"][:rows], rows - 1,
                        arrays["led_colors"][:rows],
                        altitudes[:rows] if (folder / "altitudes.npy").exists() else None)


def _mapped(path: Path) -> np.ndarray:
    """A .npy file memory-mapped (read-only); one of no rows read (there is nothing to map)."""
    try:
        return np.load(path, mmap_mode="r")
    except ValueError:
        return np.load(path)
