"""A run owns its ROS domain, or does not start (hosts/domain_claim.py)."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from composed_sim.hosts.domain_claim import (DomainClaim, DomainTaken, claim_domains, claim_free_domain, foreign_nodes,
                                             run_identity)

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"


def start(out: Path, *args, env=None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "20",
                             "--out", str(out), "--no-progress", "--no-picture", "--json", *map(str, args)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def test_a_domain_held_by_one_claim_is_refused_to_another_and_free_again_after():
    first, second = DomainClaim(), DomainClaim()
    free, domain = claim_free_domain(1, run_identity("a"), probe=False)
    try:
        holder = second.take(domain, run_identity("b"))
        assert holder == {"pid": os.getpid(), "host": holder["host"], "world": "a"}
        _, other = claim_free_domain(1, run_identity("c"), probe=False)
        assert other != domain
    finally:
        free.release()
    assert first.take(domain, run_identity("d")) is None
    first.release()


def test_two_runs_in_the_same_given_domain_the_second_refuses(tmp_path, domain_id):
    a = start(tmp_path / "a", "--ticks", "100000", "--domain-id", domain_id)
    try:
        deadline = time.monotonic() + 60
        while not list(Path("/tmp/composed_sim_domains").glob(f"domain_{domain_id}.lock")):
            assert time.monotonic() < deadline and a.poll() is None
            time.sleep(0.05)
        time.sleep(0.5)
        b = start(tmp_path / "b", "--ticks", "5", "--domain-id", domain_id)
        _, err = b.communicate(timeout=120)
        assert b.returncode == 2, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"composed-sim: error: ROS domain {domain_id} is in use by "
                                                       f"another composed-sim run (pid {a.pid} on "), err
        assert "--domain-id N or ROS_DOMAIN_ID=N" in lines[0]
    finally:
        a.kill()
        a.wait()


# Another simulator as the ROS graph shows it: a /clock publisher.
OTHER_SIMULATOR = """
import sys, time, rclpy
from rclpy.context import Context
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
context = Context(); rclpy.init(context=context, domain_id=int(sys.argv[1]))
node = Node("other_simulator", context=context)
node.create_publisher(Clock, "/clock", 10)
while True:
    time.sleep(1)
"""


# Another simulator that joins the domain once the run is under way (10 of the run's /clock came).
JOINING_SIMULATOR = """
import sys, rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
context = Context(); rclpy.init(context=context, domain_id=int(sys.argv[1]))
node = Node("joining_simulator", context=context)
seen, joined = [], []
def on_clock(msg):
    seen.append(msg)
    if len(seen) == 10:
        joined.append(node.create_publisher(Clock, "/clock", 10))
        print("joined", flush=True)
node.create_subscription(Clock, "/clock", on_clock, 10)
executor = SingleThreadedExecutor(context=context); executor.add_node(node)
while True:
    executor.spin_once(timeout_sec=0.1)
"""


@pytest.mark.parametrize("workers", [1, 2])
def test_a_simulator_joining_the_domain_during_the_run_stops_it_and_keeps_what_was_simulated(tmp_path, domain_id,
                                                                                            workers):
    # What the claim before tick 0 cannot see: another simulator in the domain later, or one its
    # probe missed. Its sensors would reach this run's controllers: the run stops, says why, and
    # writes its results so far. With workers, a worker's node finds it.
    run = start(tmp_path / "run", "--ticks", "100000", "--rate", "4", "--domain-id", domain_id, "--workers", workers)
    other = subprocess.Popen([sys.executable, "-c", JOINING_SIMULATOR, str(domain_id)], cwd=ROOT,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline() == "joined\n"
        _, err = run.communicate(timeout=60)
    finally:
        for p in (run, other):
            p.kill()
            p.wait()
    assert run.returncode == 2, err
    assert ("composed-sim: error: another simulator joined the run's ROS domain at tick " in err
            and ": node /joining_simulator (publisher GID " in err
            and "publishes /clock there too, so this run's robots hear its topics and the run stopped" in err), err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["interrupted"] and summary["ticks"] >= 9 and summary["workers"] == workers
    with np.load(tmp_path / "run" / "trajectories.npz") as saved:
        assert saved["positions"].shape == (summary["ticks"] + 1, 20, 2)


def test_the_graph_probe_finds_other_simulators_and_left_over_controllers(domain_id):
    # A controller process whose run was killed still publishes bot0's cmd_vel: the simulator
    # of a new run would get its answers. Discovery takes 0.2 s here, at times seconds, so the
    # probe is polled until it has seen both nodes.
    left = subprocess.Popen([sys.executable, "-m", "composed_sim.hosts.multiprocess.controller_process", "--world", str(FLOCKING),
                             "--robot", "bot0", "--domain", str(domain_id)], cwd=ROOT)
    other = subprocess.Popen([sys.executable, "-c", OTHER_SIMULATOR, str(domain_id)], cwd=ROOT)
    both = ["/bot0/flocking (/bot0/cmd_vel)", "/other_simulator (/clock)"]
    try:
        deadline = time.monotonic() + 60
        while (seen := foreign_nodes(domain_id)) != both:
            assert time.monotonic() < deadline and left.poll() is None and other.poll() is None, seen
        # Distributed mode: the run's own shards may be up before the simulator; only simulators count.
        while (seen := foreign_nodes(domain_id, controllers_expected=True)) != both[1:]:
            assert time.monotonic() < deadline and "/bot0/flocking (/bot0/cmd_vel)" not in seen, seen
        refusal = (f"ROS domain {domain_id} is in use by the nodes {', '.join(both)}, seen in the ROS graph; give "
                   f"this run another domain (--domain-id N or ROS_DOMAIN_ID=N), or leave both unset to pick a free one")
        message = None
        while message != refusal:
            assert time.monotonic() < deadline, message
            try:
                claim_domains([domain_id], run_identity("b"), given=True).release()
            except DomainTaken as e:
                message = str(e)
    finally:
        other.kill()
        left.terminate()
        assert left.wait(timeout=30) == 0
        other.wait()


def test_two_runs_started_together_without_a_domain_each_fly_as_alone(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    together = [start(tmp_path / f"t{seed}", "--ticks", "80", "--seed", seed, env=env) for seed in (1, 2)]
    summaries = []
    for seed, p in zip((1, 2), together):
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert "composed-sim: ROS domain " in err and "(free, picked); to watch it: an rclpy process with ROS_DOMAIN_ID=" in err
        assert json.loads(out) == json.loads((tmp_path / f"t{seed}" / "summary.json").read_text())
        summaries.append(json.loads(out))
    assert summaries[0]["domain_id"] != summaries[1]["domain_id"]
    assert [s["violations"] for s in summaries] == [0, 0]
    for seed in (1, 2):
        alone = start(tmp_path / f"a{seed}", "--ticks", "80", "--seed", seed, env=env)
        _, err = alone.communicate(timeout=300)
        assert alone.returncode == 0, err
        with np.load(tmp_path / f"t{seed}" / "trajectories.npz") as t, \
                np.load(tmp_path / f"a{seed}" / "trajectories.npz") as a:
            assert np.array_equal(t["positions"], a["positions"]) and np.array_equal(t["headings"], a["headings"])
