"""A run's results streamed to disk as it goes (outputs/stream.py): the same files as the results
kept in memory, readable during the run and after a kill up to the last checkpoint, and memory
that does not grow with the ticks. The tick loop runs over the fake exchange of
tests/hosts/test_tick_loop.py (no ROS)."""
import csv
import tracemalloc
import zipfile

import numpy as np
import pytest

from composed_sim.core.simulation import Simulation
from composed_sim.core.violations import Violation
from composed_sim.hosts.tick_loop import CHECKPOINT_EVERY, run_lockstep
from composed_sim.outputs.export import trajectory_table
from composed_sim.outputs.results import load_trajectories, summarize, write_results
from composed_sim.outputs.stream import GrowingArray, RowsFile, TrajectoryStream
from composed_sim.world.loader import load_world
from tests.hosts.test_tick_loop import WORLD, FakeExchange


def _run(ticks: int, robots: int = 4, out=None, checkpoint=None):
    world = load_world(WORLD, robots=robots, ticks=ticks, seed=2)
    sim, exchange = Simulation(world), FakeExchange(robots)
    factory = None if out is None else TrajectoryStream.factory(out, world.tick_s)
    return world, run_lockstep(sim, exchange, exchange.wait, ticks, trajectories=factory, checkpoint=checkpoint)


def _write(out, world, result, checkpoint=False):
    summary = summarize(world, result, setup_s=0.0, mode="composed", executor="lockstep", phases={})
    return write_results(out, world, result, summary, picture=False, checkpoint=checkpoint)


def test_a_streamed_run_writes_the_files_a_run_in_memory_writes(tmp_path):
    """Byte for byte: trajectories.npz (its arrays and how each member is stored), metrics.csv,
    violations.csv; and the summary's metrics."""
    world, kept = _run(250)
    _write(tmp_path / "memory", world, kept)
    world, streamed = _run(250, out=tmp_path / "stream")
    files = _write(tmp_path / "stream", world, streamed)
    assert files == ["world.yaml", "trajectories.npz", "violations.csv", "metrics.csv", "summary.json"]
    assert not (tmp_path / "stream" / "trajectories").exists()       # packed, then removed
    for name in ("metrics.csv", "violations.csv"):
        assert (tmp_path / "stream" / name).read_bytes() == (tmp_path / "memory" / name).read_bytes(), name
    with np.load(tmp_path / "memory" / "trajectories.npz") as a, np.load(tmp_path / "stream" / "trajectories.npz") as b:
        assert sorted(a) == sorted(b)
        for k in a:
            np.testing.assert_array_equal(a[k], b[k])
            assert a[k].dtype == b[k].dtype
    members = [[(i.filename, i.compress_type, i.file_size) for i in zipfile.ZipFile(d / "trajectories.npz").infolist()]
               for d in (tmp_path / "memory", tmp_path / "stream")]
    assert members[0] == members[1]
    assert streamed.metrics[0] == kept.metrics[0] and streamed.metrics[-1] == kept.metrics[-1]
    assert len(kept.metrics) > 2 and len(streamed.metrics) == 2      # memory keeps the first and the last only
    assert [(v.tick, v.robot) for v in streamed.violations] == [(3, "bot0")]


def test_after_a_kill_the_folder_reads_up_to_the_last_checkpoint(tmp_path):
    """A checkpoint flushes the stream; what was recorded after it is not part of the arrays,
    however much of it reached the files."""
    out = tmp_path / "out"
    seen = []

    def checkpoint(partial):
        _write(out, world, partial, checkpoint=True)
        seen.append(load_trajectories(out).positions.shape[0])       # readable while the run goes
    world = load_world(WORLD, robots=4, ticks=250, seed=2)
    _, result = _run(250, out=out, checkpoint=checkpoint)
    assert seen == [1, CHECKPOINT_EVERY + 1, 2 * CHECKPOINT_EVERY + 1]
    stream = result.trajectories
    for array in stream._arrays.values():
        array._file.flush()            # ticks 201..250 reach the file, as a kill leaves them, uncounted
    left = load_trajectories(out)      # the folder, as a SIGKILL leaves it
    assert left.ticks_done == 2 * CHECKPOINT_EVERY
    np.testing.assert_array_equal(left.positions, stream.positions[:2 * CHECKPOINT_EVERY + 1])
    np.testing.assert_array_equal(left.led_colors, stream.led_colors[:2 * CHECKPOINT_EVERY + 1])
    with open(out / "trajectories" / "headings.npy", "rb") as f:
        assert np.lib.format.read_array(f).shape == (2 * CHECKPOINT_EVERY + 1, 4)   # np.load without mmap too
    rows = list(csv.DictReader(open(out / "metrics.csv")))
    assert [int(r["tick"]) for r in rows] == list(range(0, 2 * CHECKPOINT_EVERY + 1, 10))
    table = trajectory_table(out)           # `composed-sim export` of the killed run
    assert table.num_rows == (2 * CHECKPOINT_EVERY + 1) * 4 and table["tick"][-1].as_py() == 2 * CHECKPOINT_EVERY


def test_a_new_run_into_the_same_out_starts_without_the_old_trajectories(tmp_path):
    world, result = _run(20, out=tmp_path)
    _write(tmp_path, world, result)
    TrajectoryStream(tmp_path, ["a"], 0.1)
    assert not (tmp_path / "trajectories.npz").exists() and not (tmp_path / "metrics.csv").exists()


def test_a_growing_array_is_a_npy_file_at_each_flush(tmp_path):
    a = GrowingArray(tmp_path / "x.npy", np.float64, (3, 2))
    rows = np.arange(6 * 1000, dtype=float).reshape(1000, 3, 2)
    assert np.load(tmp_path / "x.npy").shape == (0, 3, 2)
    for k, row in enumerate(rows, 1):
        a.append(row)
        if k in (1, 9, 10, 999, 1000):          # the header's length never changes with the count
            a.flush()
            np.testing.assert_array_equal(np.load(tmp_path / "x.npy"), rows[:k])
    with pytest.raises(ValueError, match="x.npy: a row of shape"):
        a.append(np.zeros(3))
    a.close()


def test_a_metrics_row_with_a_new_column_widens_the_file_once(tmp_path):
    rows = RowsFile(tmp_path / "m.csv")
    rows.add({"tick": 0, "a": 1})
    rows.flush()
    rows.add({"tick": 10, "a": 2, "b": 3})
    rows.add({"tick": 20, "b": 4})
    rows.flush()
    expected = [{"tick": 0, "a": 1}, {"tick": 10, "a": 2, "b": 3}, {"tick": 20, "b": 4}]
    with open(tmp_path / "memory.csv", "w", newline="") as f:     # what results.py writes from memory
        w = csv.DictWriter(f, ["tick", "a", "b"])
        w.writeheader()
        w.writerows(expected)
    assert (tmp_path / "m.csv").read_bytes() == (tmp_path / "memory.csv").read_bytes()


def test_violations_are_appended_once_each(tmp_path):
    stream = TrajectoryStream(tmp_path, ["bot0", "bot1"], 0.1)
    found = [Violation(1, "bot0", "late")]
    stream.write_violations(found)
    stream.flush()
    found += [Violation(2, "bot1", "late, again"), Violation(3, "bot0", 'a "quoted" reason')]
    stream.write_violations(found)
    stream.flush()
    stream.flush()
    got = [(int(r["tick"]), r["robot"], r["reason"]) for r in csv.DictReader(open(tmp_path / "violations.csv"))]
    assert got == [(v.tick, v.robot, v.reason) for v in found]


def test_memory_does_not_grow_with_the_ticks(tmp_path):
    """320 robots: the in-memory trajectories take 27 B a robot-tick; the stream's Python and
    numpy allocations stay under 1 MB however many ticks, with metrics taken every tick."""
    world = load_world(WORLD, robots=320, ticks=600, seed=2)
    sim = Simulation(world)
    stream = TrajectoryStream.factory(tmp_path, world.tick_s)(sim, 600)
    sizes = []
    tracemalloc.start()
    try:
        for tick in range(600):
            sim.step()
            stream.record(sim)
            stream.metrics_sink({"tick": tick, "x": float(tick)})
            if tick % CHECKPOINT_EVERY == 0:
                stream.flush()
            if tick in (100, 599):
                sizes.append(tracemalloc.get_traced_memory()[0])
    finally:
        tracemalloc.stop()
    assert sizes[1] - sizes[0] < 1 << 20, sizes
    stream.close()
    assert load_trajectories(tmp_path).positions.shape == (601, 320, 2)
