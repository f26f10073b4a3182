"""The device controller plugins through real rclpy: each world's collective behaviour emerges.

Every number asserted is measured on the run's ground-truth trajectories (or the LED colours the
simulator recorded), never taken from the controllers' own claims.
"""
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from composed_sim.world.robot_models import FOOTBOT, TURTLEBOT3_BURGER
from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world

WORLDS = Path(__file__).resolve().parents[2] / "worlds"


def run(world, domain_id):
    with ComposedHost(world, executor="lockstep", domain_id=domain_id) as host:
        return host.run()


def nearest(p: np.ndarray) -> np.ndarray:
    """[n] distance from each robot to its nearest neighbour."""
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def cells(points: np.ndarray, size_m: float = 0.5) -> int:
    """How many size_m × size_m floor cells the points fall in."""
    return len({tuple(c) for c in np.floor(points.reshape(-1, 2) / size_m).astype(int)})


def min_gap(positions: np.ndarray) -> float:
    return min(pdist(p).min() for p in positions)


def with_params(world, **params):
    g = world.robots[0]
    return world.model_copy(update={"robots": [g.model_copy(update={"params": {**g.params, **params}})]})


def test_diffusion_spreads_the_swarm_without_collisions(domain_id):
    world = load_world(WORLDS / "diffusion.yaml", ticks=300)
    result = run(world, domain_id)
    assert result.violations == []
    pos = result.trajectories.positions
    # Packed on a 0.3 m grid (0.13 m between bodies, beyond the 0.10 m IR range): they drive off
    # in their random headings and turn away from each other and the walls.
    assert nearest(pos[0]).mean() == pytest.approx(0.3)
    spread = np.mean([nearest(p).mean() for p in pos[150:]])        # over the second half
    assert spread > 0.35, spread
    # Coverage: the 0.5 m cells the swarm has been in, of the 4 × 4 m arena's 64.
    assert cells(pos[:1]) == 4 and cells(pos) >= 40, cells(pos)
    assert min_gap(pos) > 2 * FOOTBOT.body_radius_m              # no two robots ever touch
    high = world.arena.inner_bounds()[2]          # the arena is centred at the origin
    clearance = high - np.abs(pos).max() - FOOTBOT.body_radius_m
    assert clearance > -0.002, clearance     # at most resting on a wall it slides along (solver slop)


def test_turtlebots_flock_to_the_goal_with_lidar_spacing(domain_id):
    world = load_world(WORLDS / "turtlebot_flocking.yaml", ticks=300)
    result = run(world, domain_id)
    assert result.violations == []
    pos = result.trajectories.positions
    goal = np.asarray(world.robots[0].params["goal"])
    target = world.robots[0].params["target_distance_m"]
    before, after = (np.linalg.norm(pos[t].mean(axis=0) - goal) for t in (0, -1))
    # The goal vector alone drives at 7.5 cm/s: 30 s bring the flock about 2 m closer.
    assert after < before - 1.5, (before, after)
    # Lennard-Jones over LiDAR rays spreads the 0.45 m grid to about the target distance …
    assert nearest(pos[0]).mean() == pytest.approx(0.45)
    assert 0.8 * target < nearest(pos[-1]).mean() < 1.2 * target, nearest(pos[-1]).mean()
    # … and keeps them together: every robot has a neighbour within the interaction range.
    assert nearest(pos[-1]).max() < 1.8 * target
    assert min_gap(pos) > 2 * TURTLEBOT3_BURGER.body_radius_m + 0.1


def flash_ticks(led_colors: np.ndarray, start: int, period: int) -> np.ndarray:
    """[n] each robot's first lit tick in (start, start + period]; -1 when it did not flash."""
    lit = led_colors[start + 1:start + period + 1].any(axis=2)     # [period, n]
    return np.where(lit.any(axis=0), start + 1 + lit.argmax(axis=0), -1)


def order_parameter(ticks: np.ndarray, period: int) -> float:
    """Kuramoto order parameter of the flash times: 1 = all in step, ≈ 0 = spread round the cycle."""
    return float(abs(np.exp(2j * np.pi * ticks / period).mean()))


def firefly_sync(result, period):
    leds = result.trajectories.led_colors
    windows = range(0, len(leds) - 1 - period + 1, period)
    ticks = [flash_ticks(leds, s, period) for s in windows]
    assert all((t >= 0).all() for t in ticks)          # every robot flashes once per period
    return [order_parameter(t, period) for t in ticks], [np.ptp(t) for t in ticks]


def test_fireflies_synchronise_over_range_and_bearing(domain_id):
    world = load_world(WORLDS / "firefly.yaml", ticks=200)
    period = world.robots[0].params["period_ticks"]
    coupled = run(world, domain_id)
    alone = run(with_params(world, coupling=0.0), domain_id)   # same initial phases, nobody listens
    assert coupled.violations == [] and alone.violations == []
    r_alone, spread_alone = firefly_sync(alone, period)
    r_coupled, spread_coupled = firefly_sync(coupled, period)
    # Uncoupled, the random initial phases stay as they are: flashes spread round the cycle.
    assert max(r_alone) < 0.6 and min(spread_alone) >= period // 2, (r_alone, spread_alone)
    # Coupled over RAB (each hears its grid neighbours only), the spread shrinks to the
    # one-tick delay per hop of the medium and stays there.
    assert r_coupled[-1] > 0.95 and spread_coupled[-1] <= 2, (r_coupled, spread_coupled)
    assert spread_coupled[-1] < spread_coupled[0]
    assert (np.diff(spread_coupled) <= 0).all(), spread_coupled      # it never widens again


def test_aggregation_gathers_the_epucks_on_the_dark_patch(domain_id):
    world = load_world(WORLDS / "aggregation.yaml", ticks=600)
    result = run(world, domain_id)
    assert result.violations == []
    pos = result.trajectories.positions
    patch = world.floor.shapes[0]
    # A robot whose body overlaps the disc has its front ground sensors over it.
    on = np.linalg.norm(pos - np.asarray(patch.position), axis=2) < patch.radius_m + 0.035   # [T+1, n]
    fraction = on.mean(axis=1)
    # Disc area 0.5 m² of the 3.24 m² placement square: about 1/6 start on it; random walks find it, and stay.
    assert fraction[0] < 0.3 and fraction[-1] >= 0.5, (fraction[0], fraction[-1])
    assert fraction[-100:].min() >= fraction[:100].max()


def test_fireflies_in_their_own_processes_flash_as_in_composed_mode(domain_id):
    """Multi-process mode: rab_tx crosses processes and domains and lands on the same tick."""
    from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
    world = load_world(WORLDS / "firefly.yaml", robots=4, ticks=100)
    period = world.robots[0].params["period_ticks"]
    reference = run(world, domain_id)
    with MultiProcessHost(world, domain_id=101 + 4 * (os.getpid() % 32), robots_per_domain=2) as host:
        assert len(set(host.domains.values())) == 2
        result = host.run()
    assert result.violations == [] and reference.violations == []
    np.testing.assert_array_equal(result.trajectories.led_colors, reference.trajectories.led_colors)
    r, spread = firefly_sync(result, period)
    assert r[-1] > 0.95 and spread[-1] <= 1 < spread[0], (r, spread)


def test_heterogeneous_world_runs_through_the_cli(tmp_path):
    import json
    import subprocess
    import sys
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "composed_sim.cli", "run", str(WORLDS / "heterogeneous.yaml"),
                        "--ticks", "40", "--out", str(out), "--no-progress", "--no-picture", "--json"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads(r.stdout)
    assert summary["ticks"] == 40 and summary["robots"] == 14 and summary["violations"] == 0
    with np.load(out / "trajectories.npz") as t:
        moved = np.linalg.norm(t["positions"][-1] - t["positions"][0], axis=1)
    assert (moved[:6] > 0.05).all(), moved          # the foot-bots diffuse …
    assert np.median(moved[6:]) > 0.05, moved        # … and the e-pucks walk (or stopped on the patch)


def test_every_robot_model_and_device_gives_the_same_run_in_every_host_mode(domain_id):
    """Foot-bots, e-pucks, Thymios and TurtleBots in one world, each with every device it has
    switched on (range and bearing, ground, LiDAR, pose, odometry, wheels): the multi-process run,
    each controller in its own process, and the run over 3 worker processes (blocks that cut
    through groups) reproduce the composed run bit for bit."""
    from composed_sim.hosts.composed import ComposedHost
    from composed_sim.hosts.multiprocess.multiprocess_host import MultiProcessHost
    from composed_sim.hosts.workers.worker_host import WorkerHost
    from composed_sim.world.loader import world_from_dict

    always = {"positioning": {}, "odometry": {}, "differential_steering": {}}
    groups = [("foot-bot", "fb", "diffusion", {"ground": {}, "range_and_bearing": {}, **always}),
              ("e-puck", "ep", "aggregation", {"range_and_bearing": {}, **always}),
              ("thymio2", "th", "aggregation", always),
              ("turtlebot3-burger", "tb", "turtlebot-flocking", always)]
    world = world_from_dict({
        "name": "all-models", "seed": 4, "length_ticks": 30,
        "arena": {"center": [0.0, 0.0], "size": [4.0, 4.0], "walls": True},
        "floor": {"shapes": [{"type": "circle", "position": [0.0, 0.0], "radius_m": 0.5, "color": [0, 0, 0]}]},
        "robots": [{"model": model, "count": 2, "name_prefix": prefix, "controller": controller, "devices": devices,
                    "placement": {"method": "uniform", "center": [0.0, 0.0], "size": [3.4, 3.4]}}
                   for model, prefix, controller, devices in groups]})
    with ComposedHost(world, domain_id=domain_id) as host:
        composed = host.run()
    with MultiProcessHost(world, domain_id=101 + 4 * (os.getpid() % 32), robots_per_domain=3) as host:
        separate = host.run()
    with WorkerHost(world, domain_id=domain_id, workers=3) as host:
        workers = host.run()
    assert composed.violations == [] and separate.violations == [] and workers.violations == []
    for other in (separate, workers):
        for field in ("positions", "headings", "led_colors"):
            assert np.array_equal(getattr(composed.trajectories, field), getattr(other.trajectories, field)), field
    moved = np.linalg.norm(composed.trajectories.positions[-1] - composed.trajectories.positions[0], axis=1)
    assert (moved > 0.01).sum() >= 6, moved       # (an e-puck or Thymio may sit on the patch)
