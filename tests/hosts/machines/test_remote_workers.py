"""Remote workers: the simulator here, the robots on other machines (`run --machines`, `join`),
each machine's block in worker processes of its own, the world's state sent once per tick and
machine over Dask. On this machine through localhost, and across network namespaces joined by a
bridge (separate network stacks, as separate machines would be)."""
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import network_namespaces, start
from composed_sim.hosting import HostError
from composed_sim.hosts.composed import ComposedHost
from composed_sim.hosts.machines.remote_host import RemoteWorkerHost, block_state
from composed_sim.hosts.workers.shared_state import SharedState
from composed_sim.core.senses import Senses
from composed_sim.world.loader import load_world

pytest.importorskip("distributed", reason="remote workers need Dask distributed (the cluster extra)")

ROOT = Path(__file__).resolve().parents[3]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
ROBOTS, TICKS, SEED = 12, 60, 3
JOIN = [sys.executable, "-m", "composed_sim.cli", "join"]


def test_a_machine_gets_every_pose_its_blocks_rows_and_the_leds_only_when_they_changed():
    world = load_world(FLOCKING, robots=6, ticks=5, seed=1)
    shared = SharedState(Senses(world), world.range_and_bearing.payload_bytes)
    try:
        views = shared.views
        views["positions"][:] = np.arange(12).reshape(6, 2)
        views["odometry"][:] = np.arange(18).reshape(6, 3)
        sent: dict = {}
        first = block_state(views, slice(2, 4), sent)
        assert set(first) == {"positions", "headings", "led_colors", "rab_payloads", "axis_lengths",
                              "wheel_velocities", "wheel_distances", "odometry", "odometry_twist"}
        np.testing.assert_array_equal(first["odometry"], [[6, 7, 8], [9, 10, 11]])
        again = block_state(views, slice(2, 4), sent)
        assert "led_colors" not in again and "axis_lengths" not in again and "positions" in again
        views["led_colors"][5, 0] = (255, 0, 0)
        assert block_state(views, slice(2, 4), sent)["led_colors"][5, 0].tolist() == [255, 0, 0]
    finally:
        shared.close()


@pytest.mark.parametrize("args, message", [
    (["--machines", "0"], "--machines: at least one machine (got 0)"),
    (["--machines", "a,,b"], "--machines: expected a number, or addresses or host names separated by commas, "
                             "each once (got 'a,,b')"),
    (["--machines", "a,a"], "each once (got 'a,a')"),
    (["--listen", "10.0.0.1:8786"], "--listen: only for a run over machines (with --machines)"),
    (["--machines", "2", "--external-controllers"], "--machines: the robots' nodes are hosted on those machines' "
                                                    "worker processes, so --external-controllers"),
])
def test_bad_machine_flags_are_one_line_and_exit_2(args, message, capsys, tmp_path):
    from composed_sim import cli
    assert cli.main(["run", str(FLOCKING), "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("composed-sim: error: ") and message in err and "\n" not in err, err


# --- machines on this machine, through localhost -------------------------------------------------

def joining(processes, tmp_path, workers: list[str]):
    """An ``announce`` for the host: it starts one `join` per entry of ``workers`` (its --workers)
    with the very command the simulator printed."""
    def announce(line: str) -> None:
        command = line.split("on each: ", 1)[1].split()
        assert command[:2] == ["composed-sim", "join"]
        for k, count in enumerate(workers):
            processes.append(start([*JOIN, *command[2:], "--workers", count], tmp_path / f"join{k}.log"))
    return announce


def test_run_wide_services_and_topics_across_machines_match_one_process(tmp_path, processes, domain_id, monkeypatch):
    """Calls between places go in rounds the simulator leads across machines (robots call a
    run-wide planner that lives with robot 0, on the first machine), run-wide messages reach every
    machine: the same paths as in one process."""
    package = ROOT / "tests" / "user_pkg" / "robot_programs"
    monkeypatch.syspath_prepend(str(package))
    monkeypatch.setenv("PYTHONPATH", str(package))
    from tests.hosting.test_robot_programs import PROGRAMS
    world = PROGRAMS["run-wide planner"]()
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
    with RemoteWorkerHost(world, machines=2, listen="127.0.0.1:0", domain_id=domain_id, join_timeout_s=60,
                          announce=joining(processes, tmp_path, ["2", "auto"])) as host:
        result = host.run()
        sent = host.bytes_sent_per_tick(result.trajectories.ticks_done)
    assert result.violations == reference.violations == []
    np.testing.assert_array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert 0 < sent < 2 * 5 * (24 + 72) + 2000     # poses, the block's wheels and odometry, LEDs once
    for p in processes:             # the joins end with the run
        assert p.wait(timeout=30) == 0


def test_a_machine_that_never_joins_is_named_with_the_command_to_run(tmp_path, processes, domain_id):
    world = load_world(FLOCKING, robots=4, ticks=5, seed=1)
    with pytest.raises(HostError, match=r"machine 10\.9\.9\.9 did not join the run within 3 s \(joined: 127\.0\.0\.1 "
                                        r"\([^)]+\)\); on each one: composed-sim join tls://127\.0\.0\.1:\d+ --run "
                                        r"[0-9a-f]{8} --credentials \S+credentials\.pem"):
        with RemoteWorkerHost(world, machines=["127.0.0.1", "10.9.9.9"], listen="127.0.0.1:0", domain_id=domain_id,
                              join_timeout_s=3, announce=joining(processes, tmp_path, ["1"])):
            pass
    assert processes[0].wait(timeout=30) == 0       # its run is gone: the machine leaves


def test_a_machine_started_with_another_runs_command_is_refused(tmp_path, processes, domain_id):
    world = load_world(FLOCKING, robots=2, ticks=5, seed=1)
    lines = []
    with pytest.raises(HostError, match="did not join"):
        with RemoteWorkerHost(world, machines=1, listen="127.0.0.1:0", domain_id=domain_id, join_timeout_s=3,
                              announce=lines.append):
            command = lines[0].split("join ", 1)[1].split()
            address, credentials = command[0], command[command.index("--credentials") + 1]
            done = subprocess.run([*JOIN, address, "--run", "0badc0de", "--credentials", credentials, "--timeout",
                                   "10"], capture_output=True, text=True, timeout=60)
            assert done.returncode == 2
            assert re.search(r"the simulator at tls://127\.0\.0\.1:\d+ runs '[0-9a-f]{8}', not run '0badc0de'",
                             done.stderr), done.stderr


# --- across network namespaces -------------------------------------------------------------------

@pytest.fixture
def netns():
    yield from network_namespaces(["sim", "m0", "m1", "m2"])


def simulate(netns, tmp_path, machines: list[str], extra=(), robots=ROBOTS, ticks=TICKS, domain_id=0):
    """The simulator in its namespace, and the machines in theirs, each started with the command the
    simulator printed, once it printed it. Returns (simulator, joins, env)."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    addresses = ",".join(netns.address[m] for m in machines)
    sim = start(netns.exec("sim", [sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots",
                                   str(robots), "--ticks", str(ticks), "--seed", str(SEED), "--machines", addresses,
                                   "--listen", f"{netns.address['sim']}:0", "--discovery-timeout", "60",
                                   "--out", str(tmp_path / "out"), "--no-picture", "--no-progress", *extra]),
                tmp_path / "sim.log", env)
    command = wait_for_line(sim, tmp_path / "sim.log", "on each: ").split("on each: ", 1)[1].split()
    joins = [start(netns.exec(m, [*JOIN, *command[2:], "--workers", "2"]), tmp_path / f"{m}.log", env)
             for m in machines]
    return sim, joins


def wait_for_line(process: subprocess.Popen, log: Path, text: str, timeout_s: float = 60) -> str:
    """The first line of ``log`` holding ``text``, once the process wrote it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for line in log.read_text(errors="replace").splitlines():
            if text in line:
                return line
        assert process.poll() is None, log.read_text()
        time.sleep(0.05)
    raise AssertionError(f"no {text!r} in {log} after {timeout_s} s:\n{log.read_text()}")


def test_two_machines_in_other_network_namespaces_match_one_process_bit_for_bit(tmp_path, netns, domain_id,
                                                                              processes):
    world = load_world(FLOCKING, robots=ROBOTS, ticks=TICKS, seed=SEED)
    with ComposedHost(world, domain_id=domain_id) as host:
        reference = host.run()
    bag = tmp_path / "bag"        # robots' topics recorded from both machines: bot1 on the first, bot7 and bot1x on the second
    sim, joins = simulate(netns, tmp_path, ["m0", "m1"], domain_id=domain_id,
                          extra=("--record", str(bag), "--record-topics", "/bot1*/cmd_vel", "/bot7/light"))
    processes += [sim, *joins]
    assert sim.wait(timeout=120) == 0, (tmp_path / "sim.log").read_text()
    for m, join in zip(("m0", "m1"), joins):          # they end by themselves with the run
        assert join.wait(timeout=30) == 0, (tmp_path / f"{m}.log").read_text()
    # The state went through the veth links: about 24 bytes per robot and 72 per robot of the
    # machine, per tick, plus Dask's framing and TCP; the answers back.
    for m in ("m0", "m1"):
        assert netns.counters(m)["rx_bytes"] > TICKS * (ROBOTS * 24 + 6 * 72)
    out = tmp_path / "out"
    with np.load(out / "trajectories.npz") as got:
        for key in ("positions", "headings", "led_colors"):
            assert np.array_equal(got[key], getattr(reference.trajectories, key)), key
    assert (out / "violations.csv").read_text().strip() == "tick,robot,reason"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mode"] == "machines" and summary["workers"] == 2
    # Per tick every pose to each machine, each its block's wheels and odometry; the LEDs (set at
    # tick 0), payloads and axis lengths went once or twice: 2208 bytes over the 60 ticks.
    assert 0 <= summary["state_bytes_per_tick"] - (2 * ROBOTS * 24 + ROBOTS * 72) <= 2208 / TICKS + 1
    assert np.ptp(reference.trajectories.positions[:, :, 0], axis=0).max() > 0.01    # they moved
    replay = subprocess.run([sys.executable, "-m", "composed_sim.cli", "replay", str(bag), "--check"],
                            capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stderr
    assert f"{TICKS} ticks recorded" in replay.stdout
    for topic in ("/bot1/cmd_vel", "/bot10/cmd_vel", "/bot11/cmd_vel", "/bot7/light"):
        assert topic in replay.stdout, replay.stdout


def ticks_written(summary: Path) -> int:
    try:
        return json.loads(summary.read_text()).get("ticks", 0)
    except (OSError, ValueError):       # not written yet, or being written
        return 0


def test_a_machine_killed_mid_run_fails_its_robots_only_before_the_watchdog(tmp_path, netns, domain_id, processes):
    """All of a machine's processes killed (as a machine that loses power would, but its kernel
    still closes its connections): its robots fail once each at the tick it happened, none waits
    for the 2 s watchdog, the others fly on, and the run completes."""
    ticks = 400
    sim, joins = simulate(netns, tmp_path, ["m0", "m1", "m2"], extra=("--watchdog", "2"), ticks=ticks,
                          domain_id=domain_id)
    processes += [sim, *joins]
    summary = tmp_path / "out" / "summary.json"       # a checkpoint every 100 ticks
    deadline = time.monotonic() + 60
    while ticks_written(summary) < 100:
        assert sim.poll() is None and time.monotonic() < deadline, (tmp_path / "sim.log").read_text()
        time.sleep(0.05)
    netns.kill_all("m2")
    assert sim.wait(timeout=120) == 0, (tmp_path / "sim.log").read_text()
    for m, join in zip(("m0", "m1"), joins):
        assert join.wait(timeout=30) == 0, (tmp_path / f"{m}.log").read_text()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["ticks"] == ticks and not summary["interrupted"]
    rows = (tmp_path / "out" / "violations.csv").read_text().strip().splitlines()[1:]
    lost = [f"bot{i}" for i in range(8, 12)]          # robots 8-11: the third machine's block
    assert sorted((row.split(",")[1] for row in rows), key=lambda r: int(r[3:])) == lost, rows
    assert all(f"controller failed: machine {netns.address['m2']}" in row and " lost: " in row for row in rows)
    with np.load(tmp_path / "out" / "trajectories.npz") as got:
        positions = got["positions"]
    first = min(int(row.split(",")[0]) for row in rows)
    assert first >= 100
    assert np.abs(positions[first + 1:, 8:] - positions[first + 1, 8:]).max() < 1e-3    # they stand
    assert np.linalg.norm(positions[-1, :8] - positions[first + 1, :8], axis=1).min() > 0.005


@pytest.mark.slow
def test_a_machine_whose_network_goes_silent_fails_its_robots_only(tmp_path, netns, domain_id, processes):
    """Its link down (no connection closed: a cable pulled): the scheduler misses its heartbeats
    and its robots fail; the others fly on and the run completes."""
    sim, joins = simulate(netns, tmp_path, ["m0", "m1"], extra=("--watchdog", "2"), ticks=300, domain_id=domain_id)
    processes += [sim, *joins]
    summary = tmp_path / "out" / "summary.json"
    deadline = time.monotonic() + 60
    while ticks_written(summary) < 100:
        assert sim.poll() is None and time.monotonic() < deadline, (tmp_path / "sim.log").read_text()
        time.sleep(0.05)
    subprocess.run(["ip", "-n", netns.name("m1"), "link", "set", "eth0", "down"], check=True)
    assert sim.wait(timeout=120) == 0, (tmp_path / "sim.log").read_text()
    rows = (tmp_path / "out" / "violations.csv").read_text().strip().splitlines()[1:]
    assert sorted((row.split(",")[1] for row in rows), key=lambda r: int(r[3:])) == [f"bot{i}" for i in range(6, 12)]
    assert all("stopped answering the scheduler's heartbeats" in row for row in rows), rows
    assert json.loads(summary.read_text())["ticks"] == 300
