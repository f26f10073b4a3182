"""The drone-flocking plugin (controller_plugins/drone_flocking.py) on worlds/crazyflie_flocking.yaml:
a hosted rclpy node per drone, hearing its neighbours by range and bearing and streaming cmd_position.
The swarm climbs, keeps its spacing in three dimensions without a near miss, and drifts to its goal,
as measured on the run's trajectories; and flies the same in every host mode."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world

ROOT = Path(__file__).resolve().parents[2]
INTERFACES = ROOT / "tests" / "user_pkg" / "crazyflie_interfaces"


def flocking_world(robots: int = 9, ticks: int = 1000):
    world = load_world(ROOT / "worlds" / "crazyflie_flocking.yaml", robots=robots, ticks=ticks)
    return world.model_copy(update={"interfaces": [str(INTERFACES)]})


def fly(world, domain, mode: str = "composed"):
    if mode == "workers":
        from composed_sim.hosts.workers.worker_host import WorkerHost
        host = WorkerHost(world, workers=2, domain_id=domain)
    elif mode == "multi-process":
        from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
        host = MultiProcessHost(world, domain_id=domain)
    else:
        host = ComposedHost(world, domain_id=domain)
    with host:
        return host.run(), host.sim.drones.near_misses.events


def spacing(xyz: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(xyz[:, None] - xyz[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def test_the_flock_climbs_keeps_its_spacing_in_3d_and_reaches_its_goal(domain_id):
    result, near_misses = fly(flocking_world(), domain_id)
    assert result.violations == [] and near_misses == []
    t = result.trajectories
    xyz = np.concatenate([t.positions, t.altitudes[..., None]], axis=2)
    assert (t.altitudes[300:] > 0.3).all()                         # all up after 3 s
    final = spacing(xyz[-1])
    assert 0.45 < final.mean() < 1.0 and final.min() > 0.3         # target 0.8 m: a lattice, not a clump
    assert np.ptp(t.altitudes[-1]) > 0.2                           # a 3D flock, not a plane
    assert t.positions[-1, :, 0].mean() - t.positions[0, :, 0].mean() > 1.0    # towards the goal 3 m away
    steps = np.linalg.norm(np.diff(xyz, axis=0), axis=2)
    assert steps.max() <= 0.4 * 0.01 + 1e-6             # never faster than max_speed_mps (float32 setpoints)


# In multi-process mode a drone's rab_rx and pose come over DDS apart: a controller process waits
# for both before it walks, but one that arrives between its look and its walk is taken alone, and
# the drone then steers from the tick before's neighbours (a micrometre, rarely). A setpoint a tick
# late would be 4 mm (0.4 m/s at 100 Hz): what the tolerance tells apart.
SAME_FLIGHT_M = {"workers": 0.0, "multi-process": 1e-3}


@pytest.mark.parametrize("mode", ["workers", pytest.param("multi-process", marks=pytest.mark.slow)])
def test_the_flock_flies_the_same_in_every_mode(domain_id, mp_domain, mode):
    world = flocking_world(robots=6, ticks=300)
    reference, _ = fly(world, domain_id)
    result, _ = fly(world, mp_domain if mode == "multi-process" else domain_id, mode)
    assert result.violations == reference.violations == []
    tolerance = SAME_FLIGHT_M[mode]
    np.testing.assert_allclose(result.trajectories.altitudes, reference.trajectories.altitudes, rtol=0, atol=tolerance)
    np.testing.assert_allclose(result.trajectories.positions, reference.trajectories.positions, rtol=0, atol=tolerance)
