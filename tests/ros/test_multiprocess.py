"""End to end through real rclpy and real processes: the multi-process host, one OS process per
controller, robots spread over several ROS domains."""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from composed_sim.hosts.composed import ComposedHost, HostError
from composed_sim.hosts.multiprocess import MultiProcessHost
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"


@pytest.fixture
def mp_domain() -> int:
    """First of up to 4 domains for this test process, outside the 1 … 100 of conftest's
    ROS_DOMAIN_ID, so the composed run of a comparison never shares a domain with the children."""
    return 101 + 4 * (os.getpid() % 32)


def children() -> list[psutil.Process]:
    return [p for p in psutil.Process().children(recursive=True) if p.status() != psutil.STATUS_ZOMBIE]


def composed(world, domain_id, executor="lockstep"):
    with ComposedHost(world, executor=executor, domain_id=domain_id) as host:
        return host.run()


def with_controller(world, controller, params):
    return world.model_copy(update={"robots": [world.robots[0].model_copy(
        update={"controller": controller, "params": params})]})


def test_five_robots_over_three_domains_match_composed_mode(domain_id, mp_domain):
    world = load_world(FLOCKING, robots=5, ticks=60, seed=5)
    reference = composed(world, domain_id)
    with MultiProcessHost(world, domain_id=mp_domain, robots_per_domain=2) as host:
        assert sorted(set(host.domains.values())) == [mp_domain, mp_domain + 1, mp_domain + 2]
        assert len(children()) == 5 and host.setup.nodes == 5 + 3
        result = host.run()
    assert children() == []
    assert reference.violations == [] and result.violations == []
    assert np.ptp(reference.trajectories.positions[:, :, 0], axis=0).max() > 0.01   # they moved
    # Bit-identical: the same controllers on the same inputs, LEDs (the beacons) on the same tick.
    assert np.array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert np.array_equal(result.trajectories.headings, reference.trajectories.headings)


def test_plain_node_plugin_runs_in_its_own_process_too(third_party_plugin, domain_id, mp_domain):
    world = with_controller(load_world(FLOCKING, robots=2, ticks=30, seed=1), third_party_plugin, {"speed": 0.08})
    reference = composed(world, domain_id)
    with MultiProcessHost(world, executor="events", domain_id=mp_domain) as host:
        result = host.run()
    assert result.violations == []
    moved = np.linalg.norm(result.trajectories.positions[-1] - result.trajectories.positions[0], axis=1)
    assert moved.min() > 0.1, moved
    assert np.array_equal(result.trajectories.positions, reference.trajectories.positions)
    assert children() == []


def test_killed_controller_falls_back_and_the_run_finishes(mp_domain):
    world = load_world(FLOCKING, robots=3, ticks=40, seed=2)
    kill_at = 10
    with MultiProcessHost(world, domain_id=mp_domain, robots_per_domain=2) as host:
        victim = next(p for p in host.processes if p.robot == "bot1")
        done = []

        def progress(n):
            done.append(n)
            if len(done) == kill_at:
                os.kill(victim.popen.pid, signal.SIGKILL)
        result = host.run(progress=progress)
    assert children() == []
    assert result.trajectories.ticks_done == 40
    assert [(v.robot, v.reason) for v in result.violations] == [
        ("bot1", "controller failed: process killed by SIGKILL")]
    failed_at = result.violations[0].tick
    assert kill_at <= failed_at <= kill_at + 2
    # Fallback zero from then on: bot1 stands still (one tick later, as commands act), the others go on.
    pos = result.trajectories.positions
    still = pos[failed_at + 1:, 1]
    assert np.abs(still - still[0]).max() < 1e-3
    assert np.linalg.norm(pos[-1, [0, 2]] - pos[failed_at + 1, [0, 2]], axis=1).min() > 0.01


def test_a_controller_that_cannot_start_is_a_clear_error(mp_domain):
    world = load_world(FLOCKING, robots=2, ticks=5)
    bad = with_controller(world, "flocking", {**world.robots[0].params, "gian": 3.0})
    with pytest.raises(HostError, match=r"(?s)controller process of bot\d .*ended during start-up "
                                        r".*has no parameter 'gian'"):
        with MultiProcessHost(bad, domain_id=mp_domain):
            pass
    assert children() == []


def start_cli_run(tmp_path, mp_domain) -> tuple[subprocess.Popen, Path]:
    """`composed-sim run` in multi-process mode, returned once it is ticking."""
    log = tmp_path / "stderr.txt"
    cmd = [sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "3",
           "--ticks", "100000", "--mode", "multi-process", "--domain-id", str(mp_domain),
           "--out", str(tmp_path / "out"), "--no-picture"]
    # Its own session and process group, like a job in a terminal; Ctrl-C goes to that group.
    env = {**os.environ, "TMPDIR": str(tmp_path)}    # the host's temp dir too, should it be killed
    with open(log, "wb") as err:
        cli = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True, env=env)
    deadline = time.monotonic() + 60
    while not re.search(r"\b([1-9]\d*)/100000\b", log.read_text(errors="replace")):   # the progress bar
        if cli.poll() is not None or time.monotonic() > deadline:
            os.killpg(cli.pid, signal.SIGKILL)
            pytest.fail(log.read_text())
        time.sleep(0.1)
    return cli, log


def gone(processes: list[psutil.Process], timeout_s: float = 10.0) -> bool:
    _, alive = psutil.wait_procs(processes, timeout=timeout_s)
    return all(p.status() == psutil.STATUS_ZOMBIE for p in alive if p.is_running())


def test_simulator_killed_outright_takes_its_children_along(tmp_path, mp_domain):
    cli, _ = start_cli_run(tmp_path, mp_domain)
    tree = psutil.Process(cli.pid).children(recursive=True)
    assert len(tree) == 3
    cli.kill()                      # SIGKILL: no cleanup code runs; PR_SET_PDEATHSIG does the job
    cli.wait()
    assert gone(tree), [p.pid for p in tree if p.is_running()]


def test_ctrl_c_stops_at_a_tick_boundary_writes_the_summary_and_leaves_no_process(tmp_path, mp_domain):
    cli, log = start_cli_run(tmp_path, mp_domain)
    out = tmp_path / "out"
    try:
        tree = psutil.Process(cli.pid).children(recursive=True)
        assert len(tree) == 3
        os.killpg(cli.pid, signal.SIGINT)
        assert cli.wait(timeout=60) == 130, log.read_text()
    finally:
        if cli.poll() is None:
            os.killpg(cli.pid, signal.SIGKILL)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["mode"] == "multi-process"
    assert 0 < summary["ticks"] < 100000
    # The children were not interrupted before the simulator stopped: no violation at all.
    assert summary["violations"] == 0, (out / "violations.csv").read_text()
    assert gone(tree, timeout_s=0.0)
