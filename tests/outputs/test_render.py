"""Pictures and videos of a run from synthetic trajectories (headless; no ROS)."""
import time
from types import SimpleNamespace

import imageio.v3 as iio
import numpy as np
import pytest

from composed_sim.outputs.render import DEFAULT_COLOR, render
from composed_sim.world.loader import world_from_dict

N, T = 12, 30


def make_world(n=N, obstacles=True, walls=True, floor_shapes=()):
    return world_from_dict({
        "name": "render-test",
        "robots": [{"count": n, "controller": "flocking"}],
        "arena": {"size": [6, 6], "walls": walls},
        "floor": {"shapes": list(floor_shapes)},
        "lights": [{"position": [0, 2.5], "intensity": 1.0}],
        "obstacles": [{"type": "box", "position": [1.5, -1.5], "size": [0.8, 0.3], "yaw_rad": 0.5},
                      {"type": "cylinder", "position": [-1.5, -1.5], "radius_m": 0.3}] if obstacles else [],
    })


def make_run(n=N, ticks=T, seed=0):
    rng = np.random.default_rng(seed)
    headings = np.cumsum(rng.normal(0, 0.2, (ticks + 1, n)), axis=0) + rng.uniform(-np.pi, np.pi, n)
    steps = 0.05 * np.stack([np.cos(headings), np.sin(headings)], axis=-1)
    positions = rng.uniform(-2, 2, (n, 2)) + np.cumsum(steps, axis=0) - steps[0]
    leds = np.zeros((ticks + 1, n, 13, 3), dtype=np.uint8)
    leds[:, :, 12] = (255, 0, 0)
    return SimpleNamespace(positions=positions, headings=headings), leds


@pytest.fixture(scope="module")
def scene():
    return make_world(), *make_run()


def test_png_is_the_final_frame(tmp_path, scene):
    world, traj, leds = scene
    out = tmp_path / "final.png"
    assert render(traj, world, out, led_colors=leds, size_px=240) == 1
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = iio.imread(out)
    assert image.shape == (240, 240, 3)


def test_gif_has_one_frame_per_drawn_tick(tmp_path, scene):
    world, traj, leds = scene
    out = tmp_path / "run.gif"
    # every 7th tick: 0, 7, 14, 21, 28, and the last tick 30
    assert render(traj, world, out, led_colors=leds, size_px=160, every=7, fps=5) == 6
    frames = iio.imread(out, index=None)
    assert frames.shape[:3] == (6, 160, 160)
    assert not np.array_equal(frames[0], frames[-1])      # the robots moved


def test_mp4_is_readable_with_expected_frames_and_size(tmp_path, scene):
    world, traj, leds = scene
    out = tmp_path / "run.mp4"
    assert render(traj, world, out, led_colors=leds, size_px=161, fps=12, trail_ticks=10) == T + 1
    frames = list(iio.imiter(out, plugin="pyav"))
    assert len(frames) == T + 1
    assert frames[0].shape == (162, 162, 3)               # rounded up to even for H.264
    props = iio.improps(out, plugin="pyav")
    assert props.shape[1:3] == (162, 162)
    meta = iio.immeta(out, plugin="pyav")
    assert meta["fps"] == pytest.approx(12)


def count_near(image, rgb, tol=12):
    return int(np.all(np.abs(image.astype(int) - np.array(rgb)) <= tol, axis=2).sum())


def test_robots_show_their_led_colour_or_the_default(tmp_path):
    world = make_world(n=2, obstacles=False, walls=False)
    traj = SimpleNamespace(positions=np.array([[[0.0, 0.0], [0.5, 0.0]]]), headings=np.zeros((1, 2)))
    leds = np.zeros((1, 2, 13, 3), dtype=np.uint8)
    leds[0, 0, 12] = (0, 200, 0)                          # robot 0 green, robot 1 dark
    render(traj, world, tmp_path / "c.png", led_colors=leds, size_px=300)
    image = iio.imread(tmp_path / "c.png")
    assert count_near(image, (0, 200, 0)) > 20
    assert count_near(image, DEFAULT_COLOR) > 20          # a robot with every LED off
    render(traj, world, tmp_path / "d.png", size_px=300)  # no colours at all: both default
    image = iio.imread(tmp_path / "d.png")
    assert count_near(image, (0, 200, 0)) == 0 and count_near(image, DEFAULT_COLOR) > 40


def test_obstacles_and_walls_are_drawn(tmp_path):
    traj, _ = make_run(n=3, ticks=2)
    render(traj, make_world(n=3), tmp_path / "with.png", size_px=300)
    render(traj, make_world(n=3, obstacles=False, walls=False), tmp_path / "without.png", size_px=300)
    grey = (140, 140, 140)                                # obstacles: 0.55 grey
    # A 0.8 x 0.3 m box and a 0.3 m cylinder: over 500 pixels at 300 px for this 6.5 m view
    # (the rest are anti-aliased edges of text and lines).
    with_, without = (count_near(iio.imread(tmp_path / f), grey, 6) for f in ("with.png", "without.png"))
    assert with_ - without > 500


def test_shorter_colour_shapes_and_a_single_tick(tmp_path):
    world = make_world(n=3)
    traj, leds = make_run(n=3, ticks=0)
    assert render(traj, world, tmp_path / "one.gif", led_colors=leds[:, :, 12], size_px=96) == 1
    assert iio.imread(tmp_path / "one.gif", index=None).shape[0] == 1


def test_bad_arguments_are_value_errors(tmp_path, scene):
    world, traj, leds = scene
    with pytest.raises(ValueError, match="must end in"):
        render(traj, world, tmp_path / "x.avi")
    with pytest.raises(ValueError, match="headings"):
        render(SimpleNamespace(positions=traj.positions, headings=traj.headings[:, :3]), world,
               tmp_path / "x.png")
    with pytest.raises(ValueError, match="led_colors"):
        render(traj, world, tmp_path / "x.png", led_colors=leds[:3])
    with pytest.raises(ValueError, match="every"):
        render(traj, world, tmp_path / "x.gif", every=0)
    with pytest.raises(ValueError, match="size_px"):
        render(traj, world, tmp_path / "x.png", size_px=10)


@pytest.mark.slow
def test_1280_robots_600_ticks_mp4_in_reasonable_time(tmp_path):
    world = world_from_dict({"robots": [{"count": 1280, "controller": "flocking"}],
                             "lights": [{"position": [0, 10], "intensity": 3}]})
    traj, leds = make_run(n=1280, ticks=600)
    t0 = time.perf_counter()
    assert render(traj, world, tmp_path / "big.mp4", led_colors=leds) == 601
    seconds = time.perf_counter() - t0
    print(f"1280 robots x 600 ticks -> MP4 800 px: {seconds:.1f} s")
    assert seconds < 120


def test_floor_shapes_are_drawn_under_the_robots(tmp_path):
    traj, _ = make_run(n=3, ticks=2)
    plain = make_world(n=3)
    painted = make_world(n=3, floor_shapes=[
        {"type": "circle", "position": [2.0, 2.0], "radius_m": 0.5, "color": [40, 200, 40]},
        {"type": "rectangle", "position": [-2.0, 2.0], "size": [1.0, 0.6], "yaw_rad": 0.3, "color": [40, 200, 40]}])
    render(traj, painted, tmp_path / "floor.png", size_px=300)
    render(traj, plain, tmp_path / "plain.png", size_px=300)
    green = (40, 200, 40)
    # A 0.5 m disc and a 1 x 0.6 m rectangle: over 500 pixels at 300 px for this 6.5 m view.
    assert count_near(iio.imread(tmp_path / "floor.png"), green, 6) > 500
    assert count_near(iio.imread(tmp_path / "plain.png"), green, 6) == 0
