"""Initial placement: no overlaps, layouts, determinism, clear failures. No ROS."""
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from composed_sim.core.placement import (CLEARANCE_M, PlacementError, place_robots,
                                         uniform_size, wrap_angle)
from composed_sim.world.robot_models import FOOTBOT
from composed_sim.world import load_world, world_from_dict
from composed_sim.world.schema import Box, Cylinder

WORLDS = Path(__file__).resolve().parents[2] / "worlds"
R = FOOTBOT.body_radius_m
GAP = 2 * R + CLEARANCE_M       # closest allowed centre distance of two foot-bots


def world(*groups, **fields):
    return world_from_dict({"robots": [{"controller": "flocking", **g} for g in groups],
                            **fields})


def rng(seed=0):
    return np.random.default_rng(seed)


def distance_to_obstacle(p, obstacle):
    """Slow, obvious reference: distance from point p to a box or cylinder (0 inside)."""
    if isinstance(obstacle, Cylinder):
        return max(0.0, math.dist(p, obstacle.position) - obstacle.radius_m)
    c, s = math.cos(obstacle.yaw_rad), math.sin(obstacle.yaw_rad)
    dx, dy = p[0] - obstacle.position[0], p[1] - obstacle.position[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    ox = max(abs(lx) - obstacle.size[0] / 2, 0.0)
    oy = max(abs(ly) - obstacle.size[1] / 2, 0.0)
    return math.hypot(ox, oy)


def test_shapes_and_group_order():
    w = world({"count": 3, "placement": {"method": "explicit", "positions": [[0, 0], [1, 0], [2, 0]]}},
              {"count": 5, "placement": {"center": [10, 10]}})
    pos, head = place_robots(w, rng())
    assert pos.shape == (8, 2) and head.shape == (8,)
    assert pos[:3].tolist() == [[0, 0], [1, 0], [2, 0]]
    assert np.all(np.abs(pos[3:] - 10) < 1)


def test_flocking_world_has_no_overlaps_and_honours_density():
    w = load_world(WORLDS / "flocking.yaml", robots=500)
    pos, head = place_robots(w, rng(1))
    assert pdist(pos).min() >= GAP
    side = math.sqrt(500 / 5.0)         # 500 robots at 5 per m^2
    assert uniform_size(w.robots[0].placement, 500) == (side, side)
    pos = pos - np.asarray(w.robots[0].placement.center)    # relative to the square's centre
    assert np.all(np.abs(pos) <= side / 2)
    assert np.all(np.ptp(pos, axis=0) > 0.95 * side)    # the whole square is used
    # About 500 / 4 robots in each quadrant of the square: uniform, not bunched.
    quadrants = np.bincount((pos[:, 0] > 0) * 2 + (pos[:, 1] > 0), minlength=4)
    assert np.all(np.abs(quadrants - 125) < 40)
    assert np.all((head > -np.pi) & (head <= np.pi))


def test_uniform_rectangle_and_other_density():
    w = world({"count": 40, "placement": {"size": [4, 2], "center": [1, -1]}},
              {"count": 50, "name_prefix": "b", "placement": {"density": 2, "center": [20, 0]}})
    pos, _ = place_robots(w, rng())
    assert np.all(np.abs(pos[:40] - [1, -1]) <= [2, 1])
    assert np.all(np.abs(pos[40:] - [20, 0]) <= 2.5)    # side sqrt(50 / 2) = 5


def test_walled_world_avoids_walls_obstacles_and_robots():
    w = load_world(WORLDS / "flocking_walls.yaml")
    assert any(isinstance(o, Box) for o in w.obstacles) and any(
        isinstance(o, Cylinder) for o in w.obstacles)
    x0, y0, x1, y1 = w.arena.inner_bounds()
    for seed in range(20):
        pos, _ = place_robots(w, rng(seed))
        assert pdist(pos).min() >= GAP
        assert np.all((pos - R >= [x0, y0]) & (pos + R <= [x1, y1]))
        for p in pos:
            for o in w.obstacles:
                assert distance_to_obstacle(p, o) >= R + CLEARANCE_M


def test_dense_obstacles_are_drawn_around():
    # The start square is mostly covered by a yawed box and a cylinder: robots only fit
    # into what is left, and a reference check confirms none touches either.
    w = world({"count": 30, "placement": {"size": [4, 4], "max_trials": 1000}},
              obstacles=[{"type": "box", "position": [-1, 0], "size": [2.5, 1.5], "yaw_rad": 0.7},
                         {"type": "cylinder", "position": [1, 1], "radius_m": 0.9}],
              arena={"size": [4.5, 4.5], "walls": True})
    pos, _ = place_robots(w, rng())
    for p in pos:
        for o in w.obstacles:
            assert distance_to_obstacle(p, o) >= R + CLEARANCE_M
    assert np.all(np.abs(pos) <= 2.25 - 0.1 - R)


def test_grid_layout():
    w = world({"count": 10, "placement": {"method": "grid", "spacing_m": 0.5, "center": [1, 2]}})
    pos, _ = place_robots(w, rng())
    # 4 columns, 3 rows, row-major from the lower-left; the full 4 x 3 block is centred.
    expected = [[1 + (i % 4 - 1.5) * 0.5, 2 + (i // 4 - 1) * 0.5] for i in range(10)]
    np.testing.assert_allclose(pos, expected)


def test_gaussian_layout():
    w = world({"count": 400, "placement": {"method": "gaussian", "std_m": 3, "center": [5, -5]}})
    pos, _ = place_robots(w, rng())
    np.testing.assert_allclose(pos.mean(axis=0), [5, -5], atol=0.4)
    np.testing.assert_allclose(pos.std(axis=0), [3, 3], atol=0.4)
    assert pdist(pos).min() >= GAP


def test_headings():
    w = world({"count": 5, "heading": {"method": "constant", "value_rad": 3 * math.pi}},
              {"count": 2000, "name_prefix": "g", "placement": {"center": [50, 0]},
               "heading": {"method": "gaussian", "value_rad": 1.0, "std_rad": 0.2}})
    _, head = place_robots(w, rng())
    np.testing.assert_allclose(head[:5], math.pi)           # wrapped into (-pi, pi]
    assert abs(head[5:].mean() - 1.0) < 0.02 and abs(head[5:].std() - 0.2) < 0.02
    np.testing.assert_allclose(wrap_angle(np.array([-math.pi, 0.5, 7.0])),
                               [math.pi, 0.5, 7.0 - 2 * math.pi])


def test_same_seed_same_poses_other_seed_other_poses():
    w = load_world(WORLDS / "flocking_walls.yaml")
    a, b, c = (place_robots(w, rng(s)) for s in (3, 3, 4))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])


def test_later_groups_avoid_earlier_ones():
    w = world({"count": 60, "placement": {"size": [3, 3]}},
              {"count": 60, "name_prefix": "b", "placement": {"size": [3, 3]}})
    pos, _ = place_robots(w, rng())
    assert pdist(pos).min() >= GAP


@pytest.mark.parametrize("groups, fields, group_text", [
    # 200 foot-bots cannot fit into 1 m^2 (at most about 35 do).
    ([{"count": 200, "placement": {"size": [1, 1], "max_trials": 20}}], {}, "robots[0] (foot-bot"),
    ([{"count": 2},
      {"count": 2, "name_prefix": "x",
       "placement": {"method": "explicit", "positions": [[5, 5], [5.1, 5]]}}], {},
     "robots[1] (foot-bot"),
    ([{"count": 9, "placement": {"method": "grid", "spacing_m": 0.1}}], {}, "robots[0]"),
    ([{"count": 5, "placement": {"center": [10, 10], "size": [1, 1]}}],
     {"arena": {"size": [4, 4], "walls": True}}, "robots[0]"),
    ([{"count": 3, "placement": {"method": "explicit", "positions": [[0, 0], [2, 0], [4, 0]]}}],
     {"obstacles": [{"type": "cylinder", "position": [2.15, 0], "radius_m": 0.1}]}, "robots[0]"),
])
def test_impossible_placements_raise_placement_error(groups, fields, group_text):
    w = world(*groups, **fields)
    with pytest.raises(PlacementError) as info:
        place_robots(w, rng())
    message = str(info.value)
    assert group_text in message and "could not place" in message and "trial" in message
    assert info.value.unplaced > 0 and info.value.model == "foot-bot"
    assert isinstance(info.value, ValueError)


def test_placement_error_message():
    w = world({"count": 200, "placement": {"size": [1, 1], "max_trials": 20}})
    with pytest.raises(PlacementError) as info:
        place_robots(w, rng())
    e = info.value
    assert (e.group_index, e.trials) == (0, 20)
    assert str(e) == (f"robots[0] (foot-bot, bot*): could not place {e.unplaced} of 200 robots "
                      f"in 20 trials each (uniform in 1 x 1 m at (0, 0)): they overlap other "
                      f"robots, obstacles or the walls; enlarge placement.size, lower "
                      f"placement.density or raise placement.max_trials")


def test_empty_groups():
    pos, head = place_robots(world({"count": 0}), rng())
    assert pos.shape == (0, 2) and head.shape == (0,)


def test_10240_robots(capsys):
    w = load_world(WORLDS / "flocking.yaml", robots=10240)
    start = time.perf_counter()
    pos, _ = place_robots(w, rng())
    elapsed = time.perf_counter() - start
    from scipy.spatial import cKDTree
    nearest, _ = cKDTree(pos).query(pos, k=2)
    assert nearest[:, 1].min() >= GAP
    with capsys.disabled():
        print(f"\n[placement] 10240 foot-bots at 5/m^2: {elapsed * 1e3:.0f} ms")


def test_core_imports_no_ros():
    code = ("import sys, composed_sim.core.placement, composed_sim.world; "
            "assert not {'rclpy', 'matplotlib'} & set(sys.modules)")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_explicit_poses_are_taken_as_given_touching_but_not_overlapping():
    # Another simulator's poses (ARGoS's, tests/fidelity): bodies may touch; only an overlap is refused.
    touching = [[0.0, 0.0], [2 * R, 0.0]]
    w = world({"count": 2, "placement": {"method": "explicit", "positions": touching},
               "heading": {"method": "explicit", "values_rad": [0.5, 4.0]}},
              obstacles=[{"type": "cylinder", "position": [-R - 0.1, 0.0], "radius_m": 0.1}])
    pos, head = place_robots(w, rng())
    assert pos.tolist() == touching
    np.testing.assert_allclose(head, [0.5, 4.0 - 2 * math.pi])      # brought into (-π, π]
    overlapping = world({"count": 2, "placement": {"method": "explicit", "positions": [[0, 0], [2 * R - 1e-4, 0]]}})
    with pytest.raises(PlacementError):
        place_robots(overlapping, rng())


def test_explicit_headings_need_one_per_robot():
    with pytest.raises(Exception, match="values_rad"):
        world({"count": 3, "heading": {"method": "explicit", "values_rad": [0.0, 1.0]}})
    with pytest.raises(Exception, match="values_rad"):
        world({"count": 2, "heading": {"method": "explicit"}})
