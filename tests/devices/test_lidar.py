"""LiDAR: ranges at built geometries (walls, robots, heights, min/max range, mounting offset),
a looped reference on random worlds, and the noise model."""
from __future__ import annotations

import math

import numpy as np
import pytest
from reference_geometry import ref_span_box, ref_span_circle

from composed_sim.core.scene import static_scene
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.lidar import lidar_scan
from composed_sim.world.robot_models import FOOTBOT, TURTLEBOT3_BURGER, Lidar

TB = TURTLEBOT3_BURGER
LIDAR = TB.lidar
MX, MY, MZ = LIDAR.mount_m
INF = math.inf


def scan(xy, headings, observers=(0,), *, radii=None, heights=None, scene=StaticScene(), lidar=LIDAR, **kw):
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    n = len(xy)
    return lidar_scan(xy, np.asarray(headings, float), np.full(n, TB.body_radius_m) if radii is None else
                      np.asarray(radii, float), np.full(n, TB.body_height_m) if heights is None else
                      np.asarray(heights, float), np.asarray(observers), lidar, scene, **kw)


def box_scene(centre, size, yaw=0.0, height=0.5):
    from composed_sim.world.schema import Box, World
    return static_scene(World(robots=[], obstacles=[Box(position=centre, size=size, yaw_rad=yaw,
                                                                  height_m=height)]))


def test_layout_is_the_references():
    assert (LIDAR.n_rays, LIDAR.min_range_m, LIDAR.max_range_m) == (360, 0.12, 3.5)
    assert LIDAR.mount_m == (-0.064, 0.0, 0.122)
    np.testing.assert_allclose(np.degrees(LIDAR.angles_array()), np.arange(360.0), atol=1e-9)


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5])
def test_a_wall_ahead_is_measured_from_the_mount_point(heading):
    # A thin wall perpendicular to the heading, 2 m in front of the robot's centre.
    c, s = math.cos(heading), math.sin(heading)
    scene = box_scene((2.05 * c, 2.05 * s), (0.1, 4.0), yaw=heading)
    ranges = scan([[0, 0]], [heading], scene=scene)[0]
    assert ranges.shape == (360,)
    assert ranges[0] == pytest.approx(2.0 - MX)                  # the mount is 6.4 cm behind the centre
    # ray k meets the same plane at (2 - MX) / cos(k°) while it stays within the wall's 4 m
    for k in (10, 30, -20):
        assert ranges[k % 360] == pytest.approx((2.0 - MX) / math.cos(math.radians(k)))
    assert ranges[180] == INF                                     # nothing behind


def test_other_robots_are_circles_own_body_is_ignored():
    ranges = scan([[0, 0], [1.0, 0.0]], [0.0, 0.0])[0]
    assert ranges[0] == pytest.approx(1.0 - MX - TB.body_radius_m)
    # a ray grazing past the robot: the robot subtends asin(r / d) either side
    d = 1.0 - MX
    half = math.degrees(math.asin(TB.body_radius_m / d))
    assert np.isfinite(ranges[int(half) % 360]) and ranges[int(half) + 1] == INF
    assert np.isfinite(ranges[-int(half)]) and ranges[-int(half) - 1] == INF


def test_bodies_lower_than_the_scanner_are_invisible():
    r = scan([[0, 0], [1.0, 0.0]], [0.0, 0.0], heights=[TB.body_height_m, MZ - 0.01])[0]
    assert r[0] == INF
    r = scan([[0, 0]], [0.0], scene=box_scene((1.0, 0.0), (0.1, 1.0), height=MZ - 0.01))[0]
    assert r[0] == INF
    # the foot-bot (14.7 cm) is taller than the burger's scanner (12.2 cm): seen
    r = scan([[0, 0], [1.0, 0.0]], [0.0, 0.0], radii=[TB.body_radius_m, FOOTBOT.body_radius_m],
             heights=[TB.body_height_m, FOOTBOT.body_height_m])[0]
    assert r[0] == pytest.approx(1.0 - MX - FOOTBOT.body_radius_m)


def test_out_of_range_follows_rep_117():
    # a robot whose surface is 0.1 m from the mount: closer than 0.12 → -inf; beyond 3.5 → +inf
    near = MX + 0.1 + TB.body_radius_m
    assert scan([[0, 0], [near, 0.0]], [0.0, 0.0])[0][0] == -INF
    far = 3.5 + MX + TB.body_radius_m + 0.01
    assert scan([[0, 0], [far, 0.0]], [0.0, 0.0])[0][0] == INF
    assert scan([[0, 0], [far - 0.02, 0.0]], [0.0, 0.0])[0][0] == pytest.approx(3.49)


def ref_scan(xy, headings, radii, heights, i, lidar: Lidar, bodies):
    """Looped reference: every ray against every other robot and every static body."""
    h = headings[i]
    ox = xy[i][0] + math.cos(h) * lidar.mount_m[0] - math.sin(h) * lidar.mount_m[1]
    oy = xy[i][1] + math.sin(h) * lidar.mount_m[0] + math.cos(h) * lidar.mount_m[1]
    out = []
    for a in lidar.angles_array():
        far = (ox + lidar.max_range_m * math.cos(h + a), oy + lidar.max_range_m * math.sin(h + a), 0.0)
        best = INF
        for k in range(len(xy)):
            if k != i and heights[k] > lidar.mount_m[2]:
                span = ref_span_circle((ox, oy, 0.0), far, xy[k], radii[k])
                if span:
                    best = min(best, span[0] * lidar.max_range_m)
        for kind, args, height in bodies:
            if height > lidar.mount_m[2]:
                span = ref_span_circle((ox, oy, 0.0), far, *args) if kind == "cyl" else \
                    ref_span_box((ox, oy, 0.0), far, *args)
                if span:
                    best = min(best, span[0] * lidar.max_range_m)
        out.append(-INF if best < lidar.min_range_m else best)
    return out


@pytest.mark.parametrize("seed", range(3))
def test_vectorised_scan_matches_the_looped_reference(seed):
    from composed_sim.world.schema import Box, Cylinder, World
    rng = np.random.default_rng(seed)
    n = 25
    xy = rng.uniform(-2.5, 2.5, (n, 2))
    headings = rng.uniform(-math.pi, math.pi, n)
    radii = rng.choice([TB.body_radius_m, FOOTBOT.body_radius_m, 0.035], n)
    heights = rng.choice([TB.body_height_m, 0.086], n)
    obstacles = [Box(position=(0.5, 0.5), size=(0.8, 0.3), yaw_rad=0.7, height_m=0.5),
                 Cylinder(position=(-1.0, 1.0), radius_m=0.25, height_m=0.3),
                 Cylinder(position=(1.0, -1.5), radius_m=0.25, height_m=0.05)]
    scene = static_scene(World(robots=[], obstacles=obstacles))
    bodies = [("box", ((0.5, 0.5), (0.8, 0.3), 0.7), 0.5), ("cyl", ((-1.0, 1.0), 0.25), 0.3),
              ("cyl", ((1.0, -1.5), 0.25), 0.05)]
    observers = np.array([0, 3, 7, 11])
    got = lidar_scan(xy, headings, radii, heights, observers, LIDAR, scene)
    for row, i in enumerate(observers):
        np.testing.assert_allclose(got[row], ref_scan(xy, headings, radii, heights, i, LIDAR, bodies),
                                   rtol=1e-9, atol=1e-9)


def test_partial_fan():
    fan = Lidar(n_rays=5, angle_min_rad=-math.pi / 4, angle_max_rad=math.pi / 4, min_range_m=0.0,
                max_range_m=5.0, mount_m=(0.0, 0.0, 0.1))
    r = scan([[0, 0], [2.0, 0.0], [0.0, -2.0]], [0.0, 0.0, 0.0], lidar=fan)[0]
    assert r[2] == pytest.approx(2.0 - TB.body_radius_m) and np.isinf(r[[0, 1, 3, 4]]).all()


def test_gaussian_noise_on_hits_only():
    rng = np.random.default_rng(2)
    sigma = 0.01
    scene = box_scene((2.05, 0.0), (0.1, 40.0))
    xy = np.zeros((2000, 2))
    xy[:, 1] = np.arange(2000) * 0.01 - 10        # 2000 scanners facing the same wall, none in the way
    got = lidar_scan(xy, np.zeros(2000), np.full(2000, 1e-3), np.full(2000, 1e-3), np.arange(2000), LIDAR,
                     scene, noise_std_m=sigma, rng=rng)
    err = got[:, 0] - (2.0 - MX)
    assert err.mean() == pytest.approx(0.0, abs=0.001) and err.std() == pytest.approx(sigma, rel=0.05)
    assert np.isinf(got[:, 180]).all()            # no return stays +inf
