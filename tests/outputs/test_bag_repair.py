"""Recordings survive a kill: each flush leaves an MCAP file that ends on a complete record, and
`composed-sim bag repair` (or `replay`) makes what a killed run left a complete bag of its
complete ticks. A full disk stops a run with one line and keeps what was written."""
import contextlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from composed_sim.outputs.recording import writer as recording
from composed_sim.outputs.recording.repair import is_unfinished, repair
from composed_sim.cli import main
from composed_sim.outputs.recording import (CLOCK_TOPIC, FLUSH_EVERY_TICKS, SWARM_STATE_TOPIC, UNFINISHED, BagRecorder,
                                    RecordingError, read_recording)
from composed_sim.world.loader import load_world
from composed_sim.outputs.results import load_trajectories

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
NAMES = ["bot0", "bot1", "bot2"]
TICK_NS = 100_000_000


def on_disk(mcap_file: Path) -> tuple[int, bool]:
    """(/clock messages an MCAP stream reader gets from the file as it is on disk, whether the file
    ends exactly where its last complete record ends)."""
    clocks, channels, end = 0, set(), 0
    with open(mcap_file, "rb") as f:
        records = StreamReader(f).records
        with contextlib.suppress(EndOfFile):
            for record in records:
                end = f.tell()
                if isinstance(record, Channel) and record.topic == CLOCK_TOPIC:
                    channels.add(record.id)
                elif isinstance(record, Message) and record.channel_id in channels:
                    clocks += 1
    return clocks, end == mcap_file.stat().st_size


def pose(k: int) -> tuple[np.ndarray, np.ndarray]:
    return np.full((3, 2), 0.01 * k) + np.arange(3)[:, None], np.full(3, 0.1 * k)


def write_ticks(rec: BagRecorder, ticks: range) -> None:
    for k in ticks:
        rec.write_clock(k)
        rec.write_swarm_state(k * TICK_NS, *pose(k))


def killed_copy(rec: BagRecorder, dest: Path) -> Path:
    """The bag directory as a SIGKILL would leave it now: what is on disk (the recorder's
    unflushed chunk lives in its memory only)."""
    shutil.copytree(rec.path, dest)
    return dest


def test_each_flush_leaves_a_file_the_mcap_reader_reads_to_its_last_byte(tmp_path):
    rec = BagRecorder(tmp_path / "bag", robot_names=NAMES, tick_s=0.1)
    seen = []
    for k in range(2 * FLUSH_EVERY_TICKS + 5):
        write_ticks(rec, range(k, k + 1))
        clocks, whole = on_disk(rec.mcap_path)
        assert whole, f"after tick {k} the file ends inside a record"
        seen.append(clocks)
    # tick 1's /clock starts the first flush, then every 50 ticks: each flushed file holds the
    # /clock of the tick after its last complete one
    assert seen[0] == 0 and seen[1] == 2 and seen[50] == 2 and seen[51] == 52 and seen[101] == 102
    with open(rec.mcap_path, "rb") as f:      # a plain MCAP reader reads every flushed message at once
        got = []
        with contextlib.suppress(EndOfFile):
            for _, channel, _message in NonSeekingReader(f).iter_messages(log_time_order=False):
                got.append(channel.topic)
    assert got.count(CLOCK_TOPIC) == 102 and got.count(SWARM_STATE_TOPIC) == 101
    rec.close()
    assert not (tmp_path / "bag" / UNFINISHED).exists()


def test_a_slow_run_flushes_every_few_seconds_too(tmp_path, monkeypatch):
    monkeypatch.setattr(recording, "FLUSH_EVERY_S", 0.0)     # as if each tick took the whole interval
    rec = BagRecorder(tmp_path / "bag", robot_names=NAMES, tick_s=0.1)
    write_ticks(rec, range(5))
    assert on_disk(rec.mcap_path) == (5, True)
    rec.close()


def test_repair_keeps_the_complete_ticks_and_what_a_replay_needs(tmp_path):
    world = load_world(FLOCKING, robots=3, ticks=200)
    rec = BagRecorder(tmp_path / "bag", robot_names=NAMES, tick_s=0.1, world=world)
    rec.set_custom("executor", "events")
    write_ticks(rec, range(75))
    bag = killed_copy(rec, tmp_path / "killed")
    rec.close()
    assert is_unfinished(bag) and not is_unfinished(tmp_path / "bag")
    with pytest.raises(RecordingError, match="no metadata.yaml; its run was killed before closing it: composed-sim bag repair"):
        read_recording(bag)
    repaired = repair(bag)
    assert (repaired.last_tick, repaired.messages, repaired.dropped_messages) == (50, 102, 1)
    assert str(repaired) == (f"{bag}: repaired: ticks 0…50 recovered (102 messages on 2 topics); "
                             f"dropped 1 message of the unfinished tick 51")
    assert sorted(p.name for p in bag.iterdir()) == ["killed.mcap", "metadata.yaml"]
    r = read_recording(bag)
    assert r.ticks.tolist() == list(range(51)) and r.names == NAMES and r.executor == "events"
    assert r.world == world
    np.testing.assert_array_equal(r.positions[50], pose(50)[0])
    with Reader(bag) as reader:          # rosbags: metadata.yaml and the MCAP index agree
        assert reader.message_count == 102 and reader.duration == 50 * TICK_NS + 1
    with open(bag / "killed.mcap", "rb") as f:   # the seeking reader needs the summary it now has
        stamps = [m.log_time for _, c, m in make_reader(f).iter_messages(topics=[CLOCK_TOPIC])]
    assert stamps == [k * TICK_NS for k in range(51)]


def test_repair_drops_the_record_a_kill_cut_in_half(tmp_path):
    rec = BagRecorder(tmp_path / "bag", robot_names=NAMES, tick_s=0.1)
    write_ticks(rec, range(60))
    flushed = rec.mcap_path.stat().st_size
    write_ticks(rec, range(60, FLUSH_EVERY_TICKS + 52))     # the next flush, at tick 101
    bag = killed_copy(rec, tmp_path / "killed")
    rec.close()
    os.truncate(bag / "bag.mcap", flushed + 100)           # the kill came in the middle of writing it
    assert on_disk(bag / "bag.mcap") == (52, False)
    repaired = repair(bag)
    assert repaired.last_tick == 50 and repaired.dropped_bytes == 100
    assert read_recording(bag).ticks_done == 50


def test_bag_repair_says_what_it_did_in_one_line(tmp_path, capsys):
    rec = BagRecorder(tmp_path / "bag", robot_names=NAMES, tick_s=0.1)
    write_ticks(rec, range(3))              # flushed once tick 1 began: tick 0 is on disk
    bag = killed_copy(rec, tmp_path / "killed")
    rec.close()
    assert main(["bag", "repair", str(bag)]) == 0
    assert capsys.readouterr().out == f"{bag}: repaired: tick 0 recovered (2 messages on 2 topics); " \
                                      f"dropped 1 message of the unfinished tick 1\n"
    assert main(["bag", "repair", str(bag)]) == 0
    assert capsys.readouterr().out == f"{bag}: complete already (ticks 0…0): nothing to repair\n"
    (tmp_path / "notes").mkdir()
    assert main(["bag", "repair", str(tmp_path / "notes")]) == 2
    assert capsys.readouterr().err == f"composed-sim: error: {tmp_path / 'notes'}: not a recording: no .mcap files in it\n"
    assert main(["bag", "repair", str(tmp_path / "nothing")]) == 2
    assert capsys.readouterr().err.count("\n") == 1


# --- a real run, killed ------------------------------------------------------------------

def _start(tmp_path: Path, domain_id: int, *extra: str, **popen) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "20",
                             "--out", str(tmp_path / "out"), "--no-picture", "--no-progress",
                             "--domain-id", str(domain_id), *extra], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, **popen)


@pytest.fixture
def killed_run(tmp_path, domain_id) -> tuple[Path, int]:
    """(the bag of a 20-robot run killed with SIGKILL once it had flushed tick 51, the /clock
    messages on disk then)."""
    bag = tmp_path / "bag"
    proc = _start(tmp_path, domain_id, "--ticks", "100000", "--record", str(bag),
                  "--record-topics", "/bot1/cmd_vel")
    try:
        deadline = time.monotonic() + 120
        while not (bag / "bag.mcap").exists() or on_disk(bag / "bag.mcap")[0] < FLUSH_EVERY_TICKS + 2:
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)     # no clean-up runs
        proc.communicate()
    clocks, _ = on_disk(bag / "bag.mcap")
    return bag, clocks


def test_a_recording_killed_outright_is_repaired_up_to_its_last_complete_tick(killed_run, tmp_path):
    bag, clocks = killed_run
    assert not (bag / "metadata.yaml").exists() and (bag / UNFINISHED).exists()
    last = clocks - 2                       # the last /clock on disk begins a tick not complete
    copy = shutil.copytree(bag, tmp_path / "copy")
    run = subprocess.run([sys.executable, "-m", "composed_sim.cli", "bag", "repair", str(bag)], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert re.fullmatch(rf"{bag}: repaired: ticks 0…{last} recovered \(\d+ messages on 4 topics\)(; dropped .*)?\n",
                        run.stdout), run.stdout
    with Reader(bag) as reader:                                  # rosbags
        counts = {topic: info.msgcount for topic, info in reader.topics.items()}
    assert counts[CLOCK_TOPIC] == counts[SWARM_STATE_TOPIC] == counts["/swarm/markers"] == last + 1
    assert counts["/bot1/cmd_vel"] >= last
    decoded = 0
    with open(bag / "bag.mcap", "rb") as f:                      # the mcap reader and its ROS 2 decoder
        for _, _, message, ros_msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=[CLOCK_TOPIC]):
            assert ros_msg.clock.sec * 10**9 + ros_msg.clock.nanosec == message.log_time == decoded * TICK_NS
            decoded += 1
    assert decoded == last + 1
    # replay repairs a killed bag by itself, and --check re-simulates every recovered tick bit for bit
    replay = subprocess.run([sys.executable, "-m", "composed_sim.cli", "replay", str(copy), "--check"], cwd=ROOT,
                            capture_output=True, text=True, timeout=300)
    assert replay.returncode == 0, replay.stderr
    assert f"{copy}: repaired: ticks 0…{last} recovered" in replay.stderr
    assert f"check: ticks 0…{last} re-simulated" in replay.stdout


# --- a full disk -------------------------------------------------------------------------

def _limit_file_size() -> None:
    """In the run's process: files may not grow past 120 kB (a write past it fails with EFBIG;
    Python ignores SIGXFSZ, which would otherwise kill the process)."""
    resource.setrlimit(resource.RLIMIT_FSIZE, (120_000, 120_000))


@pytest.fixture(params=["tmpfs", "file size limit"])
def small_disk(request, tmp_path):
    """(a directory where a 20-robot run runs out of room after 100 to 200 ticks, the run's
    preexec_fn): a 256 kB tmpfs, which mounting needs root for (skipped where it is not allowed),
    or, anywhere, a file size limit on the run's process."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if request.param == "file size limit":
        yield disk, _limit_file_size
        return
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(disk)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    yield disk, None
    subprocess.run(["umount", str(disk)], check=True)


def test_a_full_disk_stops_the_run_with_one_line_and_keeps_what_was_written(small_disk, tmp_path, domain_id):
    disk, preexec_fn = small_disk
    out, bag = disk / "out", disk / "bag"
    proc = _start(disk, domain_id, "--ticks", "100000", "--record", str(bag), preexec_fn=preexec_fn)
    try:
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 1
    lines = [line for line in err.splitlines()        # but the lines that say the run's domain and clean-up
             if "ROS domain" not in line and "of dead processes from /dev/shm" not in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    summary = json.loads((out / "summary.json").read_text())      # a checkpoint, whole
    assert summary["checkpoint"] is True and summary["ticks"] >= 100
    assert re.fullmatch(rf"composed-sim: error: (disk full|file size limit reached): cannot write {disk}/\S+ "
                        rf"\((No space left on device|File too large)\); the run stopped at tick \d+; kept: results "
                        rf"of ticks 0…{summary['ticks']} in {out}/ and the recording up to its last flush in {bag}/ "
                        rf"\(with room again: composed-sim bag repair {bag}\)", lines[0]), lines[0]
    assert not list(out.glob("*.part"))                           # the half-written file gave its room back
    assert load_trajectories(out).positions.shape == (summary["ticks"] + 1, 20, 2)   # as streamed
    clocks, whole = on_disk(bag / "bag.mcap")                      # cut back to its last flush
    assert whole and clocks >= FLUSH_EVERY_TICKS + 2
    moved = shutil.copytree(bag, tmp_path / "bag")                 # with room again
    assert repair(moved).last_tick == clocks - 2
    assert read_recording(moved).ticks_done == clocks - 2
