"""The three sensors: the reference formulas at hand-made geometries, agreement with slow looped
references on random worlds, and the noise models."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from reference_geometry import ref_span_box, ref_span_circle
from scipy.spatial import cKDTree

from composed_sim.core.scene import static_scene
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.world.robot_models import FOOTBOT, FOOTBOT_BEACON_LED_INDEX
from composed_sim.devices.camera import BlobReadings, blob_camera, led_world_positions
from composed_sim.devices.light import light_ring
from composed_sim.devices.proximity import footbot_proximity_reading, proximity_ring
from composed_sim.world.schema import Arena, Box, Cylinder, Light, World

R, H = FOOTBOT.body_radius_m, FOOTBOT.body_height_m
CAM_H = FOOTBOT.camera.height_m
RING = FOOTBOT.proximity
LRING = FOOTBOT.light
LEDS = FOOTBOT.led_positions_array()                     # [13, 3]
SENSOR = np.array(RING.angles_rad)
RED, GREEN, BLACK = (255, 0, 0), (0, 255, 0), (0, 0, 0)


def robots(xy, headings=None, radii=None, heights=None):
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    n = len(xy)
    return (xy, np.zeros(n) if headings is None else np.asarray(headings, float),
            np.full(n, R) if radii is None else np.asarray(radii, float),
            np.full(n, H) if heights is None else np.asarray(heights, float))


def scene_of(*obstacles, arena=Arena()):
    return static_scene(World(robots=[], arena=arena, obstacles=list(obstacles)))


def reading(d):
    return 1.0 if d < 0.009889556 else 0.0100527 / (d + 0.000163144)


# ============================================================================================
# Slow, obvious references: loops over robots, sensors, bodies; plain floats.
# ============================================================================================

def wrap(a):
    a = math.fmod(a + math.pi, 2 * math.pi)
    a = a + 2 * math.pi if a <= 0 else a
    return a - math.pi                                  # (-pi, pi]


def static_bodies(world):
    """[(kind, args, height)] of the world's static bodies, walls laid out as physics.py does."""
    out = []
    a = world.arena
    if a.walls:
        (cx, cy), (sx, sy), t = a.center, a.size, a.wall_thickness_m
        for c, s in (((cx, cy + (sy + t) / 2), (sx + 2 * t, t)), ((cx, cy - (sy + t) / 2), (sx + 2 * t, t)),
                     ((cx + (sx + t) / 2, cy), (t, sy)), ((cx - (sx + t) / 2, cy), (t, sy))):
            out.append(("box", (c, s, 0.0), a.wall_height_m))
    for ob in world.obstacles:
        if isinstance(ob, Box):
            out.append(("box", (ob.position, ob.size, ob.yaw_rad), ob.height_m))
        else:
            out.append(("cyl", (ob.position, ob.radius_m), ob.height_m))
    return out


def span(kind, args, p0, p1):
    return ref_span_box(p0, p1, *args) if kind == "box" else ref_span_circle(p0, p1, *args)


def blocked(p0, p1, bodies):
    """Any body (kind, args, height) that the 3D segment crosses below its height."""
    for kind, args, h in bodies:
        s = span(kind, args, p0, p1)
        if s is not None and min(p0[2] + t * (p1[2] - p0[2]) for t in s) < h:
            return True
    return False


def robot_bodies(pos, radii, heights, skip):
    return [("cyl", (tuple(pos[j]), radii[j]), heights[j]) for j in range(len(pos)) if j not in skip]


def ref_proximity(pos, hd, radii, heights, world):
    n, k = len(pos), len(SENSOR)
    dist = np.full((n, k), np.inf)
    for i in range(n):
        bodies = [b for b in static_bodies(world) + robot_bodies(pos, radii, heights, {i})
                  if b[2] > FOOTBOT.proximity.elevation_m]
        for s in range(k):
            a = hd[i] + SENSOR[s]
            o = (pos[i][0] + radii[i] * math.cos(a), pos[i][1] + radii[i] * math.sin(a))
            e = (o[0] + RING.range_m * math.cos(a), o[1] + RING.range_m * math.sin(a))
            for kind, args, _ in bodies:
                sp = span(kind, args, o, e)
                if sp is not None:
                    dist[i, s] = min(dist[i, s], sp[0] * RING.range_m)
    readings = np.array([[0.0 if math.isinf(d) else reading(d) for d in row] for row in dist]).reshape(n, k)
    return dist, np.clip(readings, 0, 1)


def ref_light(pos, hd, radii, heights, lights, world):
    """ARGoS's footbot_light_rotzonly_sensor Update(), loop for loop."""
    n = len(pos)
    out = np.zeros((n, 24))
    spacing = math.pi / 12
    for i in range(n):
        bodies = static_bodies(world) + robot_bodies(pos, radii, heights, {i})
        for light in lights:
            if light.intensity <= 0:
                continue
            p0 = (pos[i][0], pos[i][1], 0.0)
            p1 = (light.position[0], light.position[1], light.height_m)
            if blocked(p0, p1, bodies):
                continue
            v = [(b - a) / light.intensity for a, b in zip(p0, p1)]
            angle = math.atan2(v[1], v[0]) - hd[i]
            f = (angle - spacing / 2) / spacing
            idx = int(f + 0.5) if f > 0 else int(f - 0.5)
            dist = math.sqrt(sum(c * c for c in v))
            base = 0.0 if dist > 2.5 else math.exp(-2 * dist)
            for off in range(-6, 7):
                u = (idx + off) % 24
                delta = abs(wrap(angle - SENSOR[u]))
                out[i, u] += base * (0.0 if delta > math.pi / 2 else 1 - 2 * delta / math.pi)
    return np.clip(out, 0, 1)


def ref_blobs(pos, hd, radii, heights, cam_h, half_w, led_xyz, led_rgb, world):
    """[n] lists of (angle, distance, colour) in (owner, LED) order."""
    n = len(pos)
    out = []
    for i in range(n):
        mine = []
        cam = (pos[i][0], pos[i][1], cam_h[i])
        for j in range(n):
            if j == i:
                continue
            bodies = static_bodies(world) + robot_bodies(pos, radii, heights, {i})   # owner's body hides too
            for led in range(led_xyz.shape[1]):
                rgb = tuple(int(c) for c in led_rgb[j, led])
                p = led_xyz[j, led]
                dx, dy = p[0] - pos[i][0], p[1] - pos[i][1]
                if (rgb != BLACK and abs(dx) < half_w[i] and abs(dy) < half_w[i] and p[2] < cam_h[i]
                        and not blocked(cam, tuple(p), bodies)):
                    mine.append((wrap(math.atan2(dy, dx) - hd[i]), math.hypot(dx, dy), rgb))
        out.append(mine)
    return out


def random_world(seed):
    """40 robots of assorted sizes in 3 m x 3 m, walls, boxes, cylinders, two lights, lit LEDs."""
    rng = np.random.default_rng(seed)
    n = 40
    world = World(
        robots=[],
        arena=Arena(size=(4.0, 4.0), walls=True, wall_height_m=float(rng.uniform(0.1, 0.5))),
        obstacles=[Box(position=tuple(rng.uniform(-1.8, 1.8, 2)), size=tuple(rng.uniform(0.1, 0.6, 2)),
                       height_m=float(rng.choice([0.04, 0.12, 0.4])), yaw_rad=float(rng.uniform(-3, 3)))
                   for _ in range(3)]
        + [Cylinder(position=tuple(rng.uniform(-1.8, 1.8, 2)), radius_m=float(rng.uniform(0.05, 0.3)),
                    height_m=float(rng.choice([0.04, 0.12, 0.4]))) for _ in range(3)],
        lights=[Light(position=tuple(rng.uniform(-1.9, 1.9, 2)), height_m=float(rng.uniform(0.05, 0.6)),
                      intensity=float(rng.uniform(0.5, 3))) for _ in range(2)]
        + [Light(position=(0.0, 0.0), intensity=0.0)])
    pos = rng.uniform(-1.5, 1.5, (n, 2))
    hd = rng.uniform(-math.pi, math.pi, n)
    radii = rng.uniform(0.06, 0.11, n)
    heights = rng.uniform(0.04, 0.25, n)      # some below the IR elevation, some above the beacon
    cam_h = rng.uniform(0.2, 0.35, n)
    half_w = rng.uniform(0.3, 1.8, n)
    colors = np.zeros((n, 13, 3), dtype=np.uint8)
    lit = rng.random((n, 13)) < 0.4
    colors[lit] = rng.choice([RED, GREEN, (0, 0, 255), (10, 0, 0)], size=lit.sum())
    return world, pos, hd, radii, heights, cam_h, half_w, colors


# ============================================================================================
# Proximity
# ============================================================================================

def one_robot_facing_x():
    """A robot at the origin turned so that its sensor 0 (at +7.5°) points along +x."""
    return robots([(0, 0)], headings=[-SENSOR[0]])


@pytest.mark.parametrize("d", [0.0, 0.005, 0.009, 0.0099, 0.02, 0.05, 0.0999, 0.1 - 1e-9])
def test_proximity_reading_formula_against_a_box(d):
    pos, hd, radii, heights = one_robot_facing_x()
    scene = scene_of(Box(position=(R + d + 0.5, 0), size=(1.0, 1.0)))
    dist, read = proximity_ring(pos, hd, radii, heights, RING, scene)
    assert dist[0, 0] == pytest.approx(d, abs=1e-12)
    assert read[0, 0] == pytest.approx(reading(d))
    if d < 0.009889556:
        assert read[0, 0] == 1.0
    if d > 0.0999:
        assert read[0, 0] == pytest.approx(0.10, abs=5e-4)


def test_proximity_reading_formula():
    d = np.array([0.0, 0.009889, 0.009890, 0.05, 0.10, np.inf])
    np.testing.assert_allclose(footbot_proximity_reading(d), [1, 1, 0.0100527 / (0.009890 + 0.000163144),
                                                              0.0100527 / 0.050163144, 0.100363, 0.0],
                               rtol=1e-5)


def test_proximity_beyond_range_and_nothing_around():
    pos, hd, radii, heights = one_robot_facing_x()
    dist, read = proximity_ring(pos, hd, radii, heights, RING, scene_of(Box(position=(R + 0.1001 + 0.5, 0),
                                                                           size=(1.0, 1.0))))
    assert np.isinf(dist).all() and (read == 0).all()


def test_proximity_sees_a_cylinder_a_wall_and_another_robot():
    pos, hd, radii, heights = one_robot_facing_x()
    dist, _ = proximity_ring(pos, hd, radii, heights, RING, scene_of(Cylinder(position=(R + 0.03 + 0.2, 0),
                                                                             radius_m=0.2)))
    assert dist[0, 0] == pytest.approx(0.03)
    # the +x wall's inner face is at x = 0.9 in a 2 m arena (walls 0.1 m thick, inside it)
    pos2 = np.array([[0.9 - R - 0.04, 0.0]])
    dist, _ = proximity_ring(pos2, hd, radii, heights, RING, scene_of(arena=Arena(size=(2, 2), walls=True)))
    assert dist[0, 0] == pytest.approx(0.04)
    assert np.isfinite(dist[0]).sum() == 7           # the rays within ±45°-ish of +x reach the wall
    # another robot straight ahead, rim to rim 6 cm
    pos, hd, radii, heights = robots([(0, 0), (2 * R + 0.06, 0)], headings=[-SENSOR[0], 0.0])
    dist, read = proximity_ring(pos, hd, radii, heights, RING, StaticScene())
    assert dist[0, 0] == pytest.approx(0.06) and read[0, 0] == pytest.approx(reading(0.06))
    assert np.isfinite(dist[1]).any()


def test_proximity_ignores_bodies_lower_than_the_ring_and_reads_one_when_touching():
    pos, hd, radii, heights = robots([(0, 0), (2 * R + 0.03, 0)], headings=[-SENSOR[0], 0.0],
                                     heights=[H, 0.05])
    dist, _ = proximity_ring(pos, hd, radii, heights, RING, scene_of(Box(position=(-R - 0.53, 0), size=(1, 1),
                                                                         height_m=0.05)))
    assert np.isinf(dist[0]).all()                   # the low robot and the low box are invisible
    assert np.isfinite(dist[1]).any()                # the tall robot is seen by the low one
    # overlapping robots: the rim point lies inside the other body → 0 m → reading 1
    pos, hd, radii, heights = robots([(0, 0), (2 * R - 0.01, 0)], headings=[-SENSOR[0], 0.0])
    dist, read = proximity_ring(pos, hd, radii, heights, RING, StaticScene())
    assert dist[0, 0] == 0.0 and read[0, 0] == 1.0


# ============================================================================================
# Light
# ============================================================================================

def light_at(bearing_deg, planar, height=0.3, intensity=1.0):
    b = math.radians(bearing_deg)
    return Light(position=(planar * math.cos(b), planar * math.sin(b)), height_m=height, intensity=intensity)


def test_light_ring_pattern_uses_the_13_nearest_sensors_and_the_3d_distance():
    pos, hd, radii, heights = robots([(0, 0)])
    light = light_at(20.0, 1.0, height=0.3, intensity=1.5)
    out = light_ring(pos, hd, radii, heights, LRING, [light], StaticScene())[0]
    base = math.exp(-2 * math.hypot(1.0, 0.3) / 1.5)   # 3D distance, as ARGoS (not the planar 1.0)
    nearest = 1                                        # sensor 1 at 22.5° is nearest to 20°
    window = [(nearest + o) % 24 for o in range(-6, 7)]
    assert window == [19, 20, 21, 22, 23, 0, 1, 2, 3, 4, 5, 6, 7]
    for s in range(24):
        delta = abs(wrap(math.radians(20.0) - SENSOR[s]))
        want = base * max(0.0, 1 - 2 * delta / math.pi) if s in window else 0.0
        assert out[s] == pytest.approx(want, abs=1e-12), s
    assert out[1] == out.max() and out[nearest] == pytest.approx(base * (1 - 2 * math.radians(2.5) / math.pi))
    assert (out[8:19] == 0).all()


def test_light_rotates_with_the_heading_and_lights_add_and_clamp():
    pos, hd, radii, heights = robots([(0, 0)], headings=[math.radians(90)])
    one = light_ring(pos, hd, radii, heights, LRING, [light_at(110, 2.0)], StaticScene())[0]
    ref = light_ring(*robots([(0, 0)]), LRING, [light_at(20, 2.0)], StaticScene())[0]
    np.testing.assert_allclose(one, ref, atol=1e-12)
    a, b = light_at(20, 2.0), light_at(-100, 1.0)
    two = light_ring(*robots([(0, 0)]), LRING, [a, b], StaticScene())[0]
    np.testing.assert_allclose(two, ref + light_ring(*robots([(0, 0)]), LRING, [b], StaticScene())[0])
    bright = light_ring(*robots([(0, 0)]), LRING, [light_at(20, 0.1, 0.0, 5), light_at(30, 0.1, 0.0, 5)],
                        StaticScene())[0]
    assert bright.max() == 1.0 and (bright <= 1.0).all()
    far = light_ring(*robots([(0, 0)]), LRING, [light_at(20, 2.51, 0.0, 1.0), Light(position=(0.3, 0),
                                                                                    intensity=0.0)],
                     StaticScene())
    assert (far == 0).all()                            # d' > 2.5, and intensity 0


def test_light_blocked_by_a_robot_in_between_but_not_by_one_it_passes_over():
    light = Light(position=(2.0, 0.0), height_m=0.5, intensity=1.0)
    # B at x = 0.5: the ray from A's origin enters B at x = 0.415, z = 0.104 < 0.147 → blocked
    out = light_ring(*robots([(0, 0), (0.5, 0)]), LRING, [light], StaticScene())
    assert (out[0] == 0).all() and out[1].max() > 0
    # B at x = 1.5: enters at x = 1.415, z = 0.354 → the ray passes over it
    out = light_ring(*robots([(0, 0), (1.5, 0)]), LRING, [light], StaticScene())
    alone = light_ring(*robots([(0, 0)]), LRING, [light], StaticScene())
    np.testing.assert_allclose(out[0], alone[0])
    # a low robot at x = 0.5 (5 cm tall) is passed over too; one beside the ray does not block
    out = light_ring(*robots([(0, 0), (0.5, 0), (1.0, 0.2)], heights=[H, 0.05, H]), LRING, [light],
                     StaticScene())
    np.testing.assert_allclose(out[0], alone[0])
    # a static box in between blocks, a low one does not
    assert (light_ring(*robots([(0, 0)]), LRING, [light], scene_of(Box(position=(1, 0), size=(0.2, 0.2))))
            == 0).all()
    np.testing.assert_allclose(light_ring(*robots([(0, 0)]), LRING, [light],
                                          scene_of(Box(position=(1.5, 0), size=(0.2, 0.2), height_m=0.3))),
                               alone)


# ============================================================================================
# Blob camera
# ============================================================================================

def camera(pos, hd, colors, half_w=1.0, heights=None, scene=None, **kw):
    pos, hd, radii, h = robots(pos, hd, heights=heights)
    n = len(pos)
    return blob_camera(pos, hd, radii, h, np.full(n, CAM_H), np.full(n, half_w),
                       led_world_positions(pos, hd, LEDS), np.asarray(colors, dtype=np.uint8),
                       StaticScene() if scene is None else scene, **kw)


def beacons(n, color=RED):
    c = np.zeros((n, 13, 3), dtype=np.uint8)
    c[:, FOOTBOT_BEACON_LED_INDEX] = color
    return c


def test_led_world_positions():
    p = led_world_positions(np.array([[1.0, 2.0]]), np.array([math.pi / 2]), LEDS)
    assert p.shape == (1, 13, 3)
    np.testing.assert_allclose(p[0, 12], [1, 2, 0.174249733])
    a = math.radians(15 + 90)
    r = 0.085036758 + 0.005      # footbot_entity.cpp: the body radius + 5 mm
    np.testing.assert_allclose(p[0, 0], [1 + r * math.cos(a), 2 + r * math.sin(a), 0.085], atol=1e-12)


def test_blob_square_window_not_circle():
    # half window 1 m: (0.9, 0.9) is in the square's corner, outside the inscribed circle → seen;
    # (1.1, 0.3) is inside the square's circumscribed circle but outside the square → not seen.
    b = camera([(0, 0), (0.9, 0.9), (1.1, 0.3), (-0.5, 0.99), (0, -1.01)], np.zeros(5), beacons(5))
    angles, dist, colors = b.of(0)
    assert dist.tolist() == pytest.approx([math.hypot(0.9, 0.9), math.hypot(0.5, 0.99)])
    assert angles.tolist() == pytest.approx([math.atan2(0.9, 0.9), math.atan2(0.99, -0.5)])
    assert colors.tolist() == [list(RED)] * 2
    # the window stays aligned with the world axes when the robot turns
    b = camera([(0, 0), (0.9, 0.9), (1.2, 0.0)], [math.radians(45), 0, 0], beacons(3))
    assert b.of(0)[1].tolist() == pytest.approx([math.hypot(0.9, 0.9)])


def test_blob_angles_distances_order_own_and_black_leds():
    colors = np.zeros((3, 13, 3), dtype=np.uint8)
    colors[0] = GREEN                                  # own LEDs: never seen by robot 0
    colors[1, 12] = RED
    colors[1, 7] = (0, 0, 255)                         # ring LED 7 (225°) faces robot 0
    colors[2, 12] = RED                                # robot 2's other LEDs are black
    b = camera([(0, 0), (1, 1), (-0.5, 0)], [math.pi / 2, 0.0, 0.0], colors, half_w=1.5)
    angles, dist, cols = b.of(0)
    # owner 1 first (LED 7 then the beacon), then owner 2; no own (green) LEDs, no black ones
    assert [tuple(c) for c in cols] == [(0, 0, 255), RED, RED]
    assert angles[1] == pytest.approx(-math.pi / 4) and dist[1] == pytest.approx(math.sqrt(2))
    assert angles[2] == pytest.approx(math.pi / 2) and dist[2] == pytest.approx(0.5)
    a7 = math.radians(15 + 30 * 7)
    r = 0.085036758 + 0.005                   # footbot_entity.cpp: the ring LEDs' radius
    led7 = (1 + r * math.cos(a7), 1 + r * math.sin(a7))
    assert dist[0] == pytest.approx(math.hypot(*led7))
    assert angles[0] == pytest.approx(math.atan2(led7[1], led7[0]) - math.pi / 2)
    # Robot 1 sees robot 0's beacon and the ring LEDs on the side facing it: as in ARGoS, robot
    # 0's own body hides the far side (ring LEDs sit 5 mm outside the rim, below the body's top).
    for observer, centre in ((1, (1.0, 1.0)), (2, (-0.5, 0.0))):
        seen_angles, seen_dist, seen = b.of(observer)
        green = [k for k, c in enumerate(seen) if tuple(c) == GREEN]
        assert 3 <= len(green) < 12
        centre_dist = math.hypot(*centre)
        assert any(math.isclose(seen_dist[k], centre_dist) for k in green)   # the beacon
        # Nothing beyond the LEDs abreast of the centre (distance² = d² + r²): the far side is hidden.
        assert seen_dist[green].max() <= math.hypot(centre_dist, r) + 1e-9
        assert seen_dist[green].min() < centre_dist - 0.05                   # the facing side is seen
    # robot 1 does not see robot 2's beacon: dx = -1.5 exactly, not < 1.5
    assert RED not in [tuple(c) for c in b.of(1)[2]]
    # robot 2 sees robot 1's LED 7 (dx 1.436), not its beacon (dx = 1.5)
    assert [tuple(c) for c in b.of(2)[2]][-1] == (0, 0, 255)
    assert RED not in [tuple(c) for c in b.of(2)[2]]
    assert b.offsets.dtype == np.int64 and b.offsets[:2].tolist() == [0, 3]
    assert (b.angles > -math.pi).all() and (b.angles <= math.pi).all()


def test_ring_led_hidden_by_a_robot_in_between_while_the_beacon_stays_visible():
    colors = np.zeros((3, 13, 3), dtype=np.uint8)
    colors[1] = RED                                    # B: every LED lit
    # A at 0, C at 0.8 between A and B at 1.0
    b = camera([(0, 0), (1.0, 0), (0.8, 0)], np.zeros(3), colors, half_w=1.5)
    seen = b.of(0)
    # beacon: the camera→beacon segment stays above C (z ≈ 0.19 > 0.147 over C)
    assert any(d == pytest.approx(1.0) for d in seen[1])
    # the ring LEDs facing A (165° and 195°, at x ≈ 0.913) are hidden by C
    r = 0.085036758 + 0.005                   # footbot_entity.cpp: the ring LEDs' radius
    near = math.hypot(1.0 + r * math.cos(math.radians(165)), r * math.sin(math.radians(165)))
    assert not any(d == pytest.approx(near, abs=1e-9) for d in seen[1])
    without_c = camera([(0, 0), (1.0, 0), (5, 5)], np.zeros(3), colors, half_w=1.5).of(0)
    # B's own body hides its far-side ring LEDs (as in ARGoS); the beacon and near side remain.
    assert 3 <= len(without_c[1]) < 13 and max(without_c[1]) <= math.hypot(1.0, r) + 1e-9
    assert len(seen[1]) < 13


def test_static_body_hides_blobs():
    b = camera([(0, 0), (1.0, 0)], np.zeros(2), beacons(2), half_w=1.5,
               scene=scene_of(Box(position=(0.5, 0), size=(0.1, 1.0), height_m=0.3)))
    assert len(b.of(0)[0]) == 0 and len(b.of(1)[0]) == 0
    b = camera([(0, 0), (1.0, 0)], np.zeros(2), beacons(2), half_w=1.5,
               scene=scene_of(Box(position=(0.5, 0), size=(0.1, 1.0), height_m=0.15)))
    assert len(b.of(0)[0]) == 1


# ============================================================================================
# Vectorised == looped reference on random worlds
# ============================================================================================

@pytest.mark.parametrize("seed", range(4))
def test_vectorised_sensors_match_the_looped_references(seed):
    world, pos, hd, radii, heights, cam_h, half_w, colors = random_world(seed)
    scene = static_scene(world)

    dist, read = proximity_ring(pos, hd, radii, heights, RING, scene)
    ref_d, ref_r = ref_proximity(pos, hd, radii, heights, world)
    np.testing.assert_allclose(dist, ref_d, atol=1e-9)
    np.testing.assert_allclose(read, ref_r, atol=1e-9)
    assert np.isfinite(dist).sum() > 20

    light = light_ring(pos, hd, radii, heights, LRING, world.lights, scene)
    ref = ref_light(pos, hd, radii, heights, world.lights, world)
    np.testing.assert_allclose(light, ref, atol=1e-9)
    assert (light.max(axis=1) > 0).sum() > 3 and (light.max(axis=1) == 0).sum() > 3

    led_xyz = led_world_positions(pos, hd, LEDS)
    blobs = blob_camera(pos, hd, radii, heights, cam_h, half_w, led_xyz, colors, scene)
    want = ref_blobs(pos, hd, radii, heights, cam_h, half_w, led_xyz, colors, world)
    assert np.diff(blobs.offsets).tolist() == [len(w) for w in want]
    for i, w in enumerate(want):
        a, d, c = blobs.of(i)
        if w:
            np.testing.assert_allclose(a, [x[0] for x in w], atol=1e-9)
            np.testing.assert_allclose(d, [x[1] for x in w], atol=1e-9)
            assert [tuple(x) for x in c.tolist()] == [x[2] for x in w]
    assert blobs.offsets[-1] > 50

    # one shared tree gives the same answers
    tree = cKDTree(pos)
    np.testing.assert_array_equal(proximity_ring(pos, hd, radii, heights, RING, scene, tree=tree)[0], dist)
    np.testing.assert_array_equal(light_ring(pos, hd, radii, heights, LRING, world.lights, scene, tree=tree),
                                  light)
    np.testing.assert_array_equal(blob_camera(pos, hd, radii, heights, cam_h, half_w, led_xyz, colors, scene,
                                              tree=tree).angles, blobs.angles)


@pytest.mark.parametrize("rounds", [(1, 2), (8, 4), (1000, 2)])
def test_dense_swarm_light_occlusion_matches_the_reference(monkeypatch, rounds):
    """Long rays through a dense swarm exercise the multi-round walk of the occlusion search,
    whatever its rounds (the first's samples, the growth: one round to many)."""
    import composed_sim.devices.common.sensors as sensors
    monkeypatch.setattr(sensors, "_FIRST_ROUND", rounds[0])
    monkeypatch.setattr(sensors, "_ROUND_GROWTH", rounds[1])
    rng = np.random.default_rng(11)
    pos = rng.uniform(-2, 2, (80, 2))
    hd = rng.uniform(-3, 3, 80)
    radii, heights = np.full(80, R), np.full(80, H)
    lights = [Light(position=(0, 6), height_m=0.5, intensity=3.0)]
    world = World(robots=[], lights=lights)
    got = light_ring(pos, hd, radii, heights, LRING, lights, StaticScene())
    np.testing.assert_allclose(got, ref_light(pos, hd, radii, heights, lights, world), atol=1e-9)
    lit = got.max(axis=1) > 0
    assert 0 < lit.sum() < 80


# ============================================================================================
# Noise
# ============================================================================================

def test_proximity_noise_is_uniform_and_clamped():
    rng = np.random.default_rng(5)
    n = 2000
    pos = np.column_stack([np.arange(n) * 10.0, np.zeros(n)])      # far apart: nothing is hit
    hd, radii, heights = np.full(n, -SENSOR[0]), np.full(n, R), np.full(n, H)
    dist, read = proximity_ring(pos, hd, radii, heights, RING, StaticScene(), noise=0.1, rng=rng)
    assert np.isinf(dist).all()                                    # distances stay noiseless
    assert read.min() == 0.0 and read.max() <= 0.1
    assert (read == 0).mean() == pytest.approx(0.5, abs=0.02)      # half the draws are negative
    assert read[read > 0].mean() == pytest.approx(0.05, abs=0.002)
    # around a true reading of 0.11 (a box 9 cm ahead of every robot's sensor 0)
    scene = StaticScene(box_corners=np.stack([np.array([[x, -0.5], [x + 1, -0.5], [x + 1, 0.5], [x, 0.5]])
                                              for x in pos[:, 0] + R + 0.09]), box_heights=np.full(n, 0.5))
    _, read = proximity_ring(pos, hd, radii, heights, RING, scene, noise=0.05, rng=rng)
    x = read[:, 0] - reading(0.09)
    assert abs(x).max() <= 0.05 and x.mean() == pytest.approx(0, abs=0.002)
    assert x.var() == pytest.approx(0.1 ** 2 / 12, rel=0.08)
    with pytest.raises(ValueError, match="rng"):
        proximity_ring(pos, hd, radii, heights, RING, StaticScene(), noise=0.1)
    with pytest.raises(ValueError, match="noise"):
        proximity_ring(pos, hd, radii, heights, RING, StaticScene(), noise=-1.0, rng=rng)


def test_light_noise_is_uniform_and_clamped():
    rng = np.random.default_rng(6)
    n = 500
    pos = np.column_stack([np.arange(n) * 10.0, np.zeros(n)])
    hd, radii, heights = np.zeros(n), np.full(n, R), np.full(n, H)
    out = light_ring(pos, hd, radii, heights, LRING, [], StaticScene(), noise=0.2, rng=rng)
    assert out.min() == 0.0 and out.max() <= 0.2
    assert (out == 0).mean() == pytest.approx(0.5, abs=0.02)
    assert out[out > 0].mean() == pytest.approx(0.1, abs=0.003)
    same = light_ring(pos, hd, radii, heights, LRING, [], StaticScene(), noise=0.2,
                      rng=np.random.default_rng(6))
    np.testing.assert_array_equal(out, same)                       # seeded → reproducible


def test_camera_noise_is_a_random_planar_vector_proportional_to_distance():
    rng = np.random.default_rng(8)
    n = 2000
    # pairs of robots 1 m apart along x, pairs 100 m apart from each other
    pos = np.array([(100.0 * (k // 2) + (k % 2), 0.0) for k in range(n)])
    b = camera(pos, np.zeros(n), beacons(n), half_w=1.5, noise_std=0.1, rng=rng)
    assert np.diff(b.offsets).tolist() == [1] * n
    x = b.distances * np.cos(b.angles)
    y = b.distances * np.sin(b.angles)
    true_x = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    err = np.hypot(x - true_x, y)                                  # |d| · |N(0, σ)|, d = 1 m
    assert err.mean() == pytest.approx(0.1 * math.sqrt(2 / math.pi), rel=0.1)
    assert (x - true_x).mean() == pytest.approx(0, abs=0.01) and y.mean() == pytest.approx(0, abs=0.01)
    with pytest.raises(ValueError, match="rng"):
        camera(pos, np.zeros(n), beacons(n), noise_std=0.1)


# ============================================================================================
# API details
# ============================================================================================

def test_shapes_are_checked_and_empty_inputs_work():
    pos, hd, radii, heights = robots([(0, 0), (1, 0)])
    with pytest.raises(ValueError, match="headings"):
        proximity_ring(pos, hd[:1], radii, heights, RING, StaticScene())
    with pytest.raises(ValueError, match="positions"):
        light_ring(pos[:, :1], hd, radii, heights, LRING, [], StaticScene())
    with pytest.raises(ValueError, match="led_colors"):
        blob_camera(pos, hd, radii, heights, np.full(2, CAM_H), np.ones(2), np.zeros((2, 13, 3)),
                    np.zeros((2, 12, 3)), StaticScene())
    empty = np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0)
    assert proximity_ring(*empty, RING, StaticScene())[0].shape == (0, 24)
    assert light_ring(*empty, LRING, [light_at(0, 1)], StaticScene()).shape == (0, 24)
    b = blob_camera(*empty, np.zeros(0), np.zeros(0), np.zeros((0, 13, 3)), np.zeros((0, 13, 3), np.uint8),
                    StaticScene())
    assert isinstance(b, BlobReadings) and b.offsets.tolist() == [0]


def test_core_imports_neither_rclpy_nor_matplotlib():
    code = ("import sys, composed_sim.core.simulation; "
            "print([m for m in ('rclpy', 'matplotlib') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_camera_chunks_give_the_same_blobs(monkeypatch):
    import composed_sim.devices.camera as camera
    world, pos, hd, radii, heights, cam_h, half_w, colors = random_world(9)
    scene = static_scene(world)
    args = (pos, hd, radii, heights, cam_h, half_w, led_world_positions(pos, hd, LEDS), colors, scene)
    whole = blob_camera(*args)
    monkeypatch.setattr(camera, "_BLOB_CHUNK", 50)
    parts = blob_camera(*args)
    for name in ("offsets", "angles", "distances", "colors"):
        np.testing.assert_array_equal(getattr(parts, name), getattr(whole, name))
