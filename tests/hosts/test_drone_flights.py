"""Drones commanded through their Crazyswarm2 services by a run-wide node (tests/user_pkg/drone_show):
the same world and seed fly the same, bit for bit, in one process, in worker processes and in
multi-process mode, and the flight is what the show asked for."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import importable
from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.schema import World

ROOT = Path(__file__).resolve().parents[2]
INTERFACES = ROOT / "tests" / "user_pkg" / "crazyflie_interfaces"
SHOW = ROOT / "tests" / "user_pkg" / "drone_show"
DRONES = ["cf0", "cf1", "cf2", "cf3"]


@pytest.fixture
def drone_show(monkeypatch):
    yield from importable(monkeypatch, SHOW)


def show_world() -> World:
    return World.model_validate({
        "ticks_per_second": 100, "length_ticks": 1150, "seed": 4, "interfaces": [str(INTERFACES)],
        "arena": {"size": [6.0, 6.0]},
        "robots": [{"model": "crazyflie", "count": len(DRONES), "name_prefix": "cf",
                    "placement": {"method": "grid", "spacing_m": 0.6}, "heading": {"method": "constant"}}],
        "nodes": [{"node": "drone_show.choreographer:Choreographer", "parameters": {"drones": DRONES}}]})


def fly(mode: str, domain: int):
    world = show_world()
    if mode == "workers":
        from composed_sim.hosts.workers.worker_host import WorkerHost
        host = WorkerHost(world, workers=2, domain_id=domain)
    elif mode == "multi-process":
        from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
        host = MultiProcessHost(world, domain_id=domain, robots_per_domain=2)
    else:
        host = ComposedHost(world, domain_id=domain)
    with host:
        return host.run()


def test_the_show_flies_what_it_asks(drone_show, domain_id):
    result = fly("composed", domain_id)
    assert result.violations == []
    t = result.trajectories
    ring = 580                                           # 5.8 s: the ring reached (2.6 s + 3 s)
    for k in range(len(DRONES)):
        angle = 2 * math.pi * k / len(DRONES)
        np.testing.assert_allclose(t.positions[ring, k], [math.cos(angle), math.sin(angle)], atol=1e-9)
        assert t.altitudes[ring, k] == pytest.approx(1.0 + 0.1 * k)
        assert math.remainder(t.headings[ring, k] - angle, 2 * math.pi) == pytest.approx(0.0, abs=1e-6)   # float32
    assert t.altitudes[-1].max() < 1e-9                  # landed


@pytest.mark.parametrize("mode", ["workers", "multi-process"])
def test_the_same_show_flies_the_same_in_every_mode(drone_show, domain_id, mp_domain, mode):
    reference = fly("composed", domain_id)
    result = fly(mode, mp_domain if mode == "multi-process" else domain_id)
    assert result.violations == reference.violations == []
    for field in ("positions", "headings", "altitudes"):
        np.testing.assert_array_equal(getattr(result.trajectories, field), getattr(reference.trajectories, field))


def test_drones_without_a_crazyflie_interfaces_of_the_users_have_the_shipped_one(tmp_path, domain_id):
    """Where the user built no crazyflie_interfaces the drones have their services all the same: the
    package ships with composed_sim and is built on first use (composed_sim/interfaces/activate.py).
    Before, the run went on on the floor with a warning to build Crazyswarm2's."""
    import os
    import subprocess
    import sys
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    run = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(ROOT / "worlds" / "crazyflie_grid.yaml"),
                          "--robots", "4", "--ticks", "5", "--domain-id", str(domain_id), "--out", str(tmp_path / "o"),
                          "--no-progress", "--no-picture"], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "crazyflie_interfaces" not in run.stdout + run.stderr
