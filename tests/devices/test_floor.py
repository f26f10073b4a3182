"""Floor and motor ground sensors: the grey formula, shapes, images, sensor layout, noise."""
from __future__ import annotations

import math

import imageio.v3 as iio
import numpy as np
import pytest

from composed_sim.devices.ground import ground_sensors
from composed_sim.devices.common.floor import Floor
from composed_sim.world.robot_models import EPUCK, FOOTBOT
from composed_sim.world.schema import Floor as FloorSection

FOOTBOT_GROUND = np.asarray(FOOTBOT.ground.offsets_m)


def luma(rgb):
    """docs/architecture.md: 0.299 R + 0.587 G + 0.114 B over 255."""
    r, g, b = rgb
    return (0.299 * r + 0.587 * g + 0.114 * b) / 255.0


def floor_of(**section) -> Floor:
    return Floor.from_world(FloorSection(**section))


def test_base_colour_reads_as_its_grey_level_at_every_sensor():
    floor = floor_of(color=(10, 200, 30))
    got = ground_sensors(np.array([[0.3, -2.0], [5.0, 1.0]]), np.array([0.0, 2.0]), FOOTBOT_GROUND, floor)
    assert got.shape == (2, 4)
    np.testing.assert_allclose(got, luma((10, 200, 30)))


def test_sensors_sit_at_the_body_frame_offsets_of_the_model():
    # A robot turned by 90°: its sensor at body (x, y) lies at world (-y, x) from the centre.
    centre, heading = np.array([1.0, 2.0]), math.pi / 2
    for k, (bx, by) in enumerate(FOOTBOT_GROUND):
        spot = centre + [-by, bx]
        floor = floor_of(color=(0, 0, 0), shapes=[dict(type="circle", position=tuple(spot), radius_m=0.005,
                                                       color=(255, 255, 255))])
        got = ground_sensors(centre[None], np.array([heading]), FOOTBOT_GROUND, floor)[0]
        expect = np.zeros(4)
        expect[k] = 1.0
        np.testing.assert_allclose(got, expect, atol=1e-12)


def test_shapes_paint_in_order_and_rectangles_rotate():
    floor = floor_of(color=(0, 0, 0), shapes=[
        dict(type="circle", position=(0, 0), radius_m=1.0, color=(255, 255, 255)),
        dict(type="rectangle", position=(0.5, 0), size=(1.0, 0.2), yaw_rad=math.pi / 2, color=(255, 0, 0))])
    pts = np.array([[0.0, 0.0],      # circle only
                    [0.5, 0.45],     # inside the rectangle turned upright (0.2 wide, 1.0 tall)
                    [0.9, 0.0],      # circle; outside the turned rectangle (x - 0.5 = 0.4 > 0.1)
                    [1.5, 0.0]])     # floor
    np.testing.assert_allclose(floor.grey(pts), [1.0, luma((255, 0, 0)), 1.0, 0.0])


def test_image_pixels_map_onto_their_rectangle_top_row_at_plus_y(tmp_path):
    pixels = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]],
                       [[0, 0, 0], [10, 20, 30], [100, 100, 100], [200, 0, 50]]], dtype=np.uint8)   # [2, 4, 3]
    path = tmp_path / "floor.png"
    iio.imwrite(path, pixels)
    # 4 columns over 2 m in x, 2 rows over 1 m in y, centred at (1, -1): pixels are 0.5 m squares.
    floor = floor_of(color=(7, 7, 7), image=str(path), image_size_m=(2.0, 1.0), image_center=(1.0, -1.0))
    for row in range(2):
        for col in range(4):
            x = 1.0 - 1.0 + 0.25 + 0.5 * col
            y = -1.0 + 0.5 - 0.25 - 0.5 * row
            assert floor.grey(np.array([x, y])) == pytest.approx(luma(pixels[row, col]))
    assert floor.grey(np.array([2.1, -1.0])) == pytest.approx(luma((7, 7, 7)))   # off the image


def test_image_floor_without_a_size_stretches_over_the_arena(tmp_path):
    iio.imwrite(tmp_path / "g.png", np.array([[0, 255]], dtype=np.uint8))         # grey image, 1 x 2
    floor = Floor.from_world(FloorSection(image=str(tmp_path / "g.png")), arena_size=(4.0, 4.0))
    np.testing.assert_allclose(floor.grey(np.array([[-1.0, 0.0], [1.0, 1.9]])), [0.0, 1.0])


def test_uniform_noise_statistics_and_clamp():
    rng = np.random.default_rng(5)
    a, level = 0.1, luma((128, 128, 128))
    floor = floor_of(color=(128, 128, 128))
    got = ground_sensors(np.zeros((20000, 2)), np.zeros(20000), FOOTBOT_GROUND, floor, noise=a, rng=rng)
    err = got - level
    assert np.abs(err).max() <= a
    assert err.mean() == pytest.approx(0.0, abs=0.002)
    assert err.var() == pytest.approx(a * a / 3, rel=0.03)            # uniform(-a, a)
    white = ground_sensors(np.zeros((5000, 2)), np.zeros(5000), np.asarray(EPUCK.ground.offsets_m),
                           floor_of(), noise=a, rng=rng)
    assert white.max() == 1.0 and white.min() >= 1.0 - a
    assert (white == 1.0).mean() == pytest.approx(0.5, abs=0.03)      # the upper half clamps to 1
    with pytest.raises(ValueError, match="rng"):
        ground_sensors(np.zeros((1, 2)), np.zeros(1), FOOTBOT_GROUND, floor, noise=0.1)
