"""A run owns its ROS domain, or does not start (hosts/domain_claim.py)."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from composed_sim.hosts.domain_claim import DomainClaim, claim_free_domain, run_identity

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


def test_two_runs_started_together_without_a_domain_each_fly_as_alone(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    together = [start(tmp_path / f"t{seed}", "--ticks", "80", "--seed", seed, env=env) for seed in (1, 2)]
    summaries = []
    for seed, p in zip((1, 2), together):
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        assert "composed-sim: ROS domain " in err and "(free, picked; to watch it: ROS_DOMAIN_ID=" in err
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
