"""The worker host: controller nodes in K worker processes, the physics in this one.

Same world and seed ⇒ bit-identical trajectories for every K and every executor; what the
recording taps and what outside processes see is unchanged; no worker outlives its run.
"""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosting import HostError
from composed_sim.hosting.process_hosting import EXECUTORS
from composed_sim.hosts.tick_loop import CHECKPOINT_EVERY
from composed_sim.hosts.workers.worker_host import WorkerHost, auto_workers, plan_blocks
from composed_sim.ros.taps import TapBuffer
from composed_sim.world.loader import load_world
from composed_sim.outputs.results import load_trajectories

ROOT = Path(__file__).resolve().parents[3]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
FIREFLY = ROOT / "worlds" / "firefly.yaml"


def host_for(world, workers: int, executor: str, domain_id: int):
    if workers == 1:
        return ComposedHost(world, executor=executor, domain_id=domain_id)
    return WorkerHost(world, workers=workers, executor=executor, domain_id=domain_id)


def run(world, workers: int, domain_id: int, executor: str = "lockstep", tap=None):
    with host_for(world, workers, executor, domain_id) as host:
        if tap is not None:
            host.set_message_tap(tap)
        result = host.run()
        assert host.setup.workers == workers
        return result


def assert_same_run(a, b, label: str) -> None:
    for field in ("positions", "headings", "led_colors"):
        assert np.array_equal(getattr(a.trajectories, field), getattr(b.trajectories, field)), (label, field)


@pytest.fixture(scope="module")
def flocking_single(domain_id_module):
    world = load_world(FLOCKING, robots=15, ticks=60, seed=11)
    return world, run(world, 1, domain_id_module)


@pytest.fixture(scope="module")
def domain_id_module() -> int:
    return int(os.environ["ROS_DOMAIN_ID"])


@pytest.mark.parametrize("workers", [2, 3])
def test_every_worker_count_flies_the_single_process_run_bit_for_bit(flocking_single, workers, domain_id):
    world, single = flocking_single
    assert np.ptp(single.trajectories.positions[:, :, 0], axis=0).max() > 0.01   # the robots did move
    result = run(world, workers, domain_id)
    assert result.violations == [] and single.violations == []
    assert_same_run(single, result, f"K={workers}")


@pytest.mark.parametrize("executor", [e for e in EXECUTORS if e != "lockstep"])
def test_every_executor_in_the_workers_gives_the_same_run(flocking_single, executor, domain_id):
    world, single = flocking_single
    result = run(world, 2, domain_id, executor)
    assert result.violations == []
    assert_same_run(single, result, executor)


def test_leds_and_range_and_bearing_payloads_cross_the_processes_on_the_same_tick(domain_id):
    """Fireflies flash by what they hear over range and bearing: LED colours and payloads go from
    the workers to the physics and back every tick."""
    world = load_world(FIREFLY, ticks=80)
    single, workers = run(world, 1, domain_id), run(world, 3, domain_id)
    assert single.violations == [] and workers.violations == []
    assert single.trajectories.led_colors.max() > 0          # some flashed
    assert_same_run(single, workers, "firefly K=3")


def test_the_recording_tap_gets_every_message_of_every_worker_as_in_one_process(domain_id):
    world = load_world(FLOCKING, robots=6, ticks=12, seed=2)
    taps = {}
    for workers in (1, 2):
        taps[workers] = TapBuffer(["/bot0/light", "/bot5/*"])
        run(world, workers, domain_id, tap=taps[workers])
    single, split = taps[1].drain(), taps[2].drain()
    topics = {topic for topic, *_ in single}
    # A tapped sensor topic is published even with no subscriber; leds come with the answers.
    assert topics == {"/bot0/light", "/bot5/light", "/bot5/blobs", "/bot5/proximity", "/bot5/cmd_vel", "/bot5/leds"}
    # Same topics, types, stamps and messages (compared decoded: CDR's alignment padding is
    # whatever memory the encoder's template was serialized from, per process).
    import importlib

    from rclpy.serialization import deserialize_message

    def message_class(msgtype: str):
        package, _, name = msgtype.split("/")
        return getattr(importlib.import_module(f"{package}.msg"), name)

    def decoded(messages):
        return sorted((topic, msgtype, stamp, repr(deserialize_message(data, message_class(msgtype))))
                      for topic, msgtype, data, stamp in messages)
    assert decoded(split) == decoded(single)
    stamps = sorted(stamp for topic, _, _, stamp in single if topic == "/bot5/cmd_vel")
    assert len(stamps) == 12 and len(set(stamps)) == 12


def test_blocks_are_even_and_the_auto_rule_follows_cores_and_size():
    assert plan_blocks(7, 3) == [(0, 2), (2, 4), (4, 7)]
    assert plan_blocks(1280, 2) == [(0, 640), (640, 1280)]
    with pytest.raises(ValueError):
        plan_blocks(3, 4)
    assert auto_workers(40, cores=2) == 1            # small swarms stay in one process
    assert auto_workers(1280, cores=2) >= 2
    assert auto_workers(1280, cores=16) == 16
    assert auto_workers(1280, cores=1) >= 2 and auto_workers(10240, cores=1) >= auto_workers(1280, cores=1)


def test_the_workers_are_forked_by_one_launcher_adopted_here_and_reaped(domain_id, monkeypatch):
    """One launcher imports the workers' code once and forks them; this process adopts them
    (they are its children, each in a process group of its own, each with its own log) and
    reaps every one at the end. One core: the workers build their nodes one after the other."""
    monkeypatch.setattr("composed_sim.hosts.workers.worker_host.usable_cores", lambda: 1)
    world = load_world(FLOCKING, robots=9, ticks=5, seed=3)
    this = psutil.Process()
    with WorkerHost(world, workers=3, domain_id=domain_id) as host:
        pids = [w.popen.pid for w in host.workers]
        children = {p.pid: p for p in this.children()}
        assert set(pids) <= set(children), (pids, children)
        assert len({os.getpgid(pid) for pid in pids}) == 3 and all(os.getpgid(pid) == pid for pid in pids)
        assert all("composed_sim.hosts.workers.launcher" in " ".join(children[pid].cmdline()) for pid in pids)
        assert len({w.log for w in host.workers}) == 3 and all(w.log.exists() for w in host.workers)
        result = host.run()
    assert result.violations == [] and result.trajectories.ticks_done == 5
    for pid in pids:            # reaped: not even a zombie is left
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_more_workers_than_robots_is_a_clear_error():
    world = load_world(FLOCKING, robots=2, ticks=5)
    with pytest.raises(HostError, match="--workers 3: a worker hosts at least one of the 2 robots"):
        WorkerHost(world, workers=3)


def _start_run(tmp_path, domain_id: int, workers: int) -> tuple[subprocess.Popen, Path]:
    log = tmp_path / "run.log"
    with open(log, "wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "6",
                                 "--ticks", "100000", "--workers", str(workers), "--out", str(tmp_path / "out"),
                                 "--no-picture", "--domain-id", str(domain_id)], cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
    deadline = time.monotonic() + 120
    while "tick/s" not in log.read_text(errors="replace"):        # the progress bar: ticking
        if proc.poll() is not None or time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(log.read_text())
        time.sleep(0.1)
    return proc, log


def _workers_of(proc: subprocess.Popen) -> list[psutil.Process]:
    return [p for p in psutil.Process(proc.pid).children(recursive=True)
            if "composed_sim.hosts.workers.launcher" in p.cmdline()]


def _running(processes: list[psutil.Process]) -> list[int]:
    _, alive = psutil.wait_procs(processes, timeout=10)
    return [p.pid for p in alive if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


def test_a_main_process_killed_outright_takes_its_workers_and_leaves_its_last_checkpoint(tmp_path, domain_id):
    proc, log = _start_run(tmp_path, domain_id, workers=2)
    workers = _workers_of(proc)
    assert len(workers) == 2, log.read_text()
    summary_file = tmp_path / "out" / "summary.json"
    deadline = time.monotonic() + 60
    def checkpointed_ticks() -> int:
        try:
            return json.loads(summary_file.read_text())["ticks"]
        except (OSError, ValueError):       # not written yet (files are replaced whole, never half)
            return -1
    while checkpointed_ticks() < CHECKPOINT_EVERY:      # past the tick-0 checkpoint, at tick 100
        assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
        time.sleep(0.05)
    proc.kill()                     # SIGKILL: no clean-up runs; PR_SET_PDEATHSIG takes the workers
    proc.wait()
    assert _running(workers) == []
    summary = json.loads(summary_file.read_text())
    assert summary["checkpoint"] is True and summary["ticks"] >= CHECKPOINT_EVERY
    assert summary["ticks"] % CHECKPOINT_EVERY == 0
    # The trajectories as the run streamed them (outputs/stream.py), whole up to that checkpoint.
    t = load_trajectories(tmp_path / "out")
    assert not (tmp_path / "out" / "trajectories.npz").exists()
    assert t.positions.shape == (summary["ticks"] + 1, 6, 2)
    assert np.ptp(t.positions[:, :, 0], axis=0).max() > 0.01
    assert (tmp_path / "out" / "violations.csv").read_text().startswith("tick,robot,reason")


def test_ctrl_c_stops_a_worker_run_at_a_tick_boundary_and_writes_everything(tmp_path, domain_id):
    proc, log = _start_run(tmp_path, domain_id, workers=2)
    workers = _workers_of(proc)
    try:
        proc.send_signal(signal.SIGINT)     # the main process only: the workers ignore it
        assert proc.wait(timeout=60) == 130, log.read_text()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["workers"] == 2 and summary["ticks"] > 0
    assert summary["violations"] == 0, (tmp_path / "out" / "violations.csv").read_text()
    with np.load(tmp_path / "out" / "trajectories.npz") as t:
        assert t["positions"].shape == (summary["ticks"] + 1, 6, 2)
    assert _running(workers) == []


def _with_noise(path: Path, tmp_path: Path, after: str, lines: str) -> Path:
    """The shipped world with ``lines`` (noise settings) put after the line ``after``."""
    text = path.read_text()
    assert after in text
    noisy = tmp_path / path.name
    noisy.write_text(text.replace(after, after + lines, 1))
    return noisy


WHEELS = "      wheels: {factor_std: 0.1, bias_std_mps: 0.002}\n"


@pytest.mark.parametrize("shipped, after, lines", [
    (FLOCKING, "      aperture_deg: 80.0\n",
     "    devices:\n      proximity: {noise: 0.05}\n      light: {noise: 0.05}\n      camera: {noise_std: 0.05}\n"
     "      positioning: {position_noise_m: 0.01, yaw_noise_rad: 0.02}\n" + WHEELS),
    (FIREFLY, "        range_m: 0.9         # grid neighbours (0.6 m) and diagonals (0.85 m), no further\n",
     "        packet_drop_probability: 0.3\n        noise_std_m: 0.05\n" + WHEELS),
])
def test_noise_is_drawn_per_robot_so_every_worker_count_reads_the_same_noisy_sensors(shipped, after, lines, tmp_path,
                                                                                      domain_id):
    """Each worker reads its own robots' sensors, with every device's noise on: the draws depend
    on the robot, the tick and the reading, not on which process reads them."""
    world = load_world(_with_noise(shipped, tmp_path, after, lines), robots=12, ticks=40, seed=4)
    quiet = load_world(shipped, robots=12, ticks=40, seed=4)
    single, three, without = run(world, 1, domain_id), run(world, 3, domain_id), run(quiet, 1, domain_id)
    assert single.violations == [] and three.violations == []
    assert_same_run(single, three, f"{shipped.name} with noise, K=3")
    # The noise acts: the foot-bots move otherwise, the fireflies (standing) flash otherwise.
    assert any(not np.array_equal(getattr(single.trajectories, f), getattr(without.trajectories, f))
               for f in ("positions", "led_colors"))
