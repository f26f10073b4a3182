"""`composed-sim replay BAG --check` proves a recording: it re-simulates the world the bag holds
(its seed, its executor) and compares every recorded tick bit for bit."""
import subprocess
import sys
from pathlib import Path

import pytest

from composed_sim.outputs.recording import BagRecorder, read_recording

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
TICKS = 60


def cli(*args):
    return subprocess.run([sys.executable, "-m", "composed_sim.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("replay")
    r = cli("run", FLOCKING, "--robots", 6, "--ticks", TICKS, "--out", tmp / "out", "--record", tmp / "bag",
            "--no-progress", "--no-picture")
    assert r.returncode == 0, r.stderr[-2000:]
    return tmp / "bag"


def rewritten(bag: Path, out: Path, *, skip=(), move=None, world=None) -> Path:
    """A copy of ``bag``'s clock and swarm state, ticks ``skip`` left out, ``move`` = (tick, robot,
    dx) applied, ``world`` stored instead of the recorded one."""
    rec = read_recording(bag)
    positions = rec.positions.copy()
    if move is not None:
        tick, robot, dx = move
        positions[tick, robot, 0] += dx
    with BagRecorder(out, robot_names=rec.names, tick_s=rec.tick_s, world=world or rec.world) as writer:
        writer.set_custom("executor", rec.executor)
        for i, tick in enumerate(rec.ticks):
            if tick in skip:
                continue
            stamp = int(rec.stamps_ns[i])
            writer.write_clock(int(tick), stamp)
            writer.write_swarm_state(stamp, positions[i], rec.headings[i], rec.led_colors[i])
    return out


def test_a_good_recording_passes_and_its_tick_count_agrees_with_the_summary(bag):
    r = cli("replay", bag, "--check")
    assert r.returncode == 0, r.stderr
    assert f"ticks 0…{TICKS} re-simulated (seed" in r.stdout and "identical, bit for bit" in r.stdout
    assert f"{TICKS} ticks recorded" in r.stdout
    import yaml
    custom = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["custom_data"]
    assert custom["composed_sim.ticks"] == str(TICKS) and custom["composed_sim.executor"] == "lockstep"


def test_a_gap_fails_naming_the_first_missing_tick(bag, tmp_path):
    r = cli("replay", rewritten(bag, tmp_path / "gap", skip=range(40, 51)), "--check")
    assert r.returncode == 1 and "check failed: tick 40 is missing" in r.stderr, r.stderr


def test_an_edited_pose_fails_naming_tick_and_robot(bag, tmp_path):
    r = cli("replay", rewritten(bag, tmp_path / "moved", move=(50, 3, 3.0)), "--check")
    assert r.returncode == 1 and "check failed: tick 50, bot3: the recorded position" in r.stderr, r.stderr


def test_an_edited_world_fails_at_the_first_tick_it_changes(bag, tmp_path):
    rec = read_recording(bag)
    group = rec.world.robots[0]
    gain = group.params["gain"]
    edited = rec.world.model_copy(update={"robots": [group.model_copy(update={"params": {**group.params,
                                                                                          "gain": gain * 3}})]})
    r = cli("replay", rewritten(bag, tmp_path / "edited", world=edited), "--check")
    assert r.returncode == 1 and "check failed: tick " in r.stderr, r.stderr
    tick = int(r.stderr.split("check failed: tick ")[1].split(",")[0])
    assert 1 <= tick <= TICKS     # tick 0 is the placement, which the gain does not touch
