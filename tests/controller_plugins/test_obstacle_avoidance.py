"""The shipped ROS-style TurtleBot 3 node (controller_plugins/obstacle_avoidance.py: scan with
sensor-data QoS, 10 Hz timer, unstamped Twist) drives around its obstacle world without touching."""
from pathlib import Path

import numpy as np

from composed_sim.hosts.composed import ComposedHost
from composed_sim.world.loader import load_world
from composed_sim.world.robot_models import get_model

WORLD = Path(__file__).resolve().parents[2] / "worlds" / "turtlebot_obstacles.yaml"


def clearance(world, positions: np.ndarray) -> np.ndarray:
    """[..., 2] robot centres → [...] distance to the nearest obstacle or wall surface (m)."""
    out = []
    for o in world.obstacles:
        if o.type == "cylinder":
            out.append(np.linalg.norm(positions - np.array(o.position), axis=-1) - o.radius_m)
        else:                                   # signed distance to a rotated rectangle
            c, s = np.cos(o.yaw_rad), np.sin(o.yaw_rad)
            d = positions - np.array(o.position)
            local = np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1)
            e = np.abs(local) - np.array(o.size) / 2
            out.append(np.linalg.norm(np.maximum(e, 0), axis=-1) + np.minimum(e.max(axis=-1), 0))
    out.append((np.array(world.arena.size) / 2 - np.abs(positions - np.array(world.arena.center))).min(axis=-1))
    return np.min(out, axis=0)


def run(world, domain_id):
    with ComposedHost(world, executor="lockstep", domain_id=domain_id) as host:
        return host.run()


def test_burgers_roam_without_touching_anything(domain_id):
    world = load_world(WORLD, ticks=300)
    result = run(world, domain_id)
    assert result.violations == []
    pos = result.trajectories.positions
    radius = get_model("turtlebot3-burger").body_radius_m
    assert clearance(world, pos).min() > radius + 0.05
    travelled = np.linalg.norm(np.diff(pos, axis=0), axis=2).sum(axis=0)
    assert (travelled > 3.0).all(), travelled          # 30 s at up to 0.15 m/s: they keep going
    # The same robots that do not stop drive into the first obstacle ahead and stay there.
    reckless = world.model_copy(update={"robots": [world.robots[0].model_copy(
        update={"params": {**world.robots[0].params, "stop_distance_m": 0.0}})]})
    assert clearance(reckless, run(reckless, domain_id).trajectories.positions).min() < radius + 0.01
