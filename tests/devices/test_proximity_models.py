"""Proximity layouts and calibrations of the other robots, and sensing for a subset of robots."""
from __future__ import annotations

import math

import numpy as np
import pytest

from composed_sim.core.scene import static_scene
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.world.robot_models import EPUCK, FOOTBOT, THYMIO2
from composed_sim.devices.camera import blob_camera, led_world_positions
from composed_sim.devices.light import light_ring
from composed_sim.devices.proximity import epuck_proximity_reading, proximity_ring
from composed_sim.world.schema import Box, Light, World


def wall_at_x(x, height=0.5):
    return static_scene(World(robots=[], obstacles=[Box(position=(x + 0.05, 0.0), size=(0.1, 2.0),
                                                                  height_m=height)]))


def test_epuck_calibration_is_argos_quadratic_clamped():
    d = np.array([0.0, 0.01, 0.03, 0.049, 0.06, np.inf])
    expect = [min(1.0, max(0.0, 298.701 * x * x - 36.8961 * x + 1.08212)) if x <= 0.05 else 0.0 for x in d]
    np.testing.assert_allclose(epuck_proximity_reading(d), expect)
    # by hand: 298.701 · 0.0009 - 36.8961 · 0.03 + 1.08212 = 0.2688309 - 1.106883 + 1.08212
    assert epuck_proximity_reading(np.array([0.03]))[0] == pytest.approx(0.2440679, abs=1e-7)


def test_epuck_ring_is_argos_active_layout():
    # epuck_entity.cpp's active code: π / 10.5884, π / 3.5999, π/2, π/1.2, π/0.8571, π/0.6667,
    # π/0.5806, π/0.5247 (normalised): about 17°, 50°, 90°, 150°, -150°, -90°, -50°, -17°.
    degrees = np.degrees(EPUCK.proximity.angles_rad)
    np.testing.assert_allclose(degrees, [17.0, 50.0, 90.0, 150.0, -150.0, -90.0, -50.0, -17.0], atol=0.06)
    assert degrees[0] == pytest.approx(180.0 / 10.5884, rel=1e-6)


def test_epuck_ring_sees_a_wall_with_its_front_sensors():
    # e-puck at the origin facing +x; wall face 4 cm in front of the rim. The sensors at about
    # ±17° and ±50° reach it within their 10 cm; the side (±90°) and back (±150°) ones do not.
    dist, read = proximity_ring(np.zeros((1, 2)), np.zeros(1), np.array([EPUCK.body_radius_m]),
                                np.array([EPUCK.body_height_m]), EPUCK.proximity,
                                wall_at_x(EPUCK.body_radius_m + 0.04))
    a = np.abs(np.asarray(EPUCK.proximity.angles_rad)[[0, 1, 6, 7]])
    along = (EPUCK.body_radius_m + 0.04 - EPUCK.body_radius_m * np.cos(a)) / np.cos(a)
    assert along[0] == pytest.approx(0.0434, abs=1e-4) and along[1] == pytest.approx(0.0817, abs=1e-4)
    np.testing.assert_allclose(dist[0, [0, 1, 6, 7]], along)
    np.testing.assert_allclose(read[0, [0, 1, 6, 7]], epuck_proximity_reading(along))
    assert np.isinf(dist[0, 2:6]).all() and not read[0, 2:6].any()


def test_thymio_sensors_start_at_their_body_points():
    # Thymio facing +x, wall face at x = 0.2: the middle front sensor (7.95 cm ahead, pointing
    # forward) measures 0.2 - 0.0795; the outer ones (40°) would need 0.18 m > their 0.14 m range.
    dist, read = proximity_ring(np.zeros((1, 2)), np.zeros(1), np.array([THYMIO2.body_radius_m]),
                                np.array([THYMIO2.body_height_m]), THYMIO2.proximity, wall_at_x(0.2))
    assert dist[0, 2] == pytest.approx(0.2 - 0.0795)
    assert dist[0, 1] == pytest.approx((0.2 - 0.075) / math.cos(0.34906))
    assert np.isinf(dist[0, [0, 4, 5, 6]]).all()
    assert read[0, 2] == pytest.approx(math.exp(-(0.2 - 0.0795)))          # ARGoS generic: exp(-d)
    # turned around, the two back sensors see a wall behind: 2.95 cm behind the axle
    dist, _ = proximity_ring(np.zeros((1, 2)), np.array([math.pi]), np.array([THYMIO2.body_radius_m]),
                             np.array([THYMIO2.body_height_m]), THYMIO2.proximity, wall_at_x(0.1))
    np.testing.assert_allclose(dist[0, 5:], 0.1 - 0.0295)


def test_another_robot_is_seen_from_offset_origins():
    xy = np.array([[0.0, 0.0], [0.2, 0.0]])
    dist, _ = proximity_ring(xy, np.zeros(2), np.array([THYMIO2.body_radius_m, FOOTBOT.body_radius_m]),
                             np.array([THYMIO2.body_height_m, FOOTBOT.body_height_m]), THYMIO2.proximity,
                             StaticScene())
    assert dist[0, 2] == pytest.approx(0.2 - FOOTBOT.body_radius_m - 0.0795)


@pytest.mark.parametrize("seed", range(3))
def test_sensing_a_subset_gives_those_rows_of_sensing_all(seed):
    rng = np.random.default_rng(seed)
    n = 60
    xy = rng.uniform(-2, 2, (n, 2))
    h = rng.uniform(-math.pi, math.pi, n)
    radii = np.full(n, FOOTBOT.body_radius_m)
    heights = np.full(n, FOOTBOT.body_height_m)
    scene = static_scene(World(robots=[], obstacles=[Box(position=(0.3, 0.2), size=(0.5, 0.5))]))
    subset = np.sort(rng.choice(n, 17, replace=False))
    d_all, r_all = proximity_ring(xy, h, radii, heights, FOOTBOT.proximity, scene)
    d_sub, r_sub = proximity_ring(xy, h, radii, heights, FOOTBOT.proximity, scene, observers=subset)
    np.testing.assert_array_equal(d_sub, d_all[subset])
    lights = [Light(position=(0.0, 3.0), intensity=2.0)]
    np.testing.assert_array_equal(light_ring(xy, h, radii, heights, FOOTBOT.light, lights, scene, observers=subset),
                                  light_ring(xy, h, radii, heights, FOOTBOT.light, lights, scene)[subset])
    leds = led_world_positions(xy, h, FOOTBOT.led_positions_array())
    colors = np.zeros((n, FOOTBOT.n_leds, 3), np.uint8)
    colors[:, 12] = (255, 0, 0)
    colors[::3, 0] = (0, 255, 0)
    args = (xy, h, radii, heights, np.full(n, FOOTBOT.camera.height_m), np.full(n, 1.6), leds, colors, scene)
    every, some = blob_camera(*args), blob_camera(*args, observers=subset)
    assert len(some.offsets) == len(subset) + 1 and some.offsets[-1] > 0
    for row, i in enumerate(subset):
        for x, y in zip(some.of(row), every.of(i)):
            np.testing.assert_array_equal(x, y)
