"""Range-and-bearing: the reference's reading at built geometries, range limits per sender,
occlusion, global mode, a looped reference on random worlds, packet drop and noise statistics."""
from __future__ import annotations

import math

import numpy as np
import pytest
from reference_geometry import ref_span_box, ref_span_circle

from composed_sim.core.scene import static_scene
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.range_and_bearing import range_and_bearing
from composed_sim.world.robot_models import EPUCK, FOOTBOT
from composed_sim.world.schema import Box, Cylinder, World

R, H = FOOTBOT.body_radius_m, FOOTBOT.body_height_m
Z = FOOTBOT.range_and_bearing.elevation_m
EMPTY = StaticScene()


def rab(xy, headings=None, *, ranges=3.0, elevations=Z, radii=R, heights=H, payloads=None, scene=EMPTY,
        equipped=None, **kw):
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    n = len(xy)
    full = lambda v: np.broadcast_to(np.asarray(v, float), (n,)).copy()
    payloads = np.arange(n, dtype=np.uint8)[:, None].repeat(4, axis=1) if payloads is None else payloads
    return range_and_bearing(xy, full(0.0 if headings is None else headings), full(radii), full(heights),
                             np.ones(n, bool) if equipped is None else np.asarray(equipped), full(elevations),
                             full(ranges), payloads, scene, **kw)


def heard(readings, i):
    return sorted(readings.of(i)[0].tolist())


def test_reading_of_a_neighbour_range_bearings_and_payload():
    # Receiver 0 faces +y; the sender is 1 m along +x, i.e. on the receiver's right.
    r = rab([[0, 0], [1, 0]], [math.pi / 2, 0.0])
    senders, ranges, hb, vb, data = r.of(0)
    assert senders.tolist() == [1]
    assert ranges[0] == pytest.approx(1.0) and hb[0] == pytest.approx(-math.pi / 2) and vb[0] == 0.0
    assert data.tolist() == [[1, 1, 1, 1]]
    # and the sender sees the receiver straight behind it
    assert r.of(1)[2][0] == pytest.approx(math.pi)


def test_emitters_at_different_heights_give_the_3d_range_and_the_elevation():
    dz = EPUCK.range_and_bearing.elevation_m - Z       # an e-puck's RAB is lower than the foot-bot's
    r = rab([[0, 0], [0.5, 0]], elevations=[Z, EPUCK.range_and_bearing.elevation_m])
    _, ranges, _, vb, _ = r.of(0)
    assert ranges[0] == pytest.approx(math.hypot(0.5, dz))
    assert vb[0] == pytest.approx(math.atan2(dz, 0.5)) and vb[0] < 0
    assert r.of(1)[3][0] == pytest.approx(-vb[0])


def test_the_senders_range_decides():
    # 0 emits 0.5 m, 1 emits 3 m; 1 m apart: 0 hears 1, 1 does not hear 0 (docs/architecture.md).
    r = rab([[0, 0], [1, 0]], ranges=[0.5, 3.0])
    assert heard(r, 0) == [1] and heard(r, 1) == []
    r = rab([[0, 0], [2.99, 0]])
    assert heard(r, 0) == [1]
    r = rab([[0, 0], [3.01, 0]])
    assert heard(r, 0) == []


def test_a_robot_in_between_or_a_tall_obstacle_occludes_a_low_one_does_not():
    line = [[0, 0], [1, 0], [2, 0]]
    r = rab(line)
    assert heard(r, 0) == [1] and heard(r, 2) == [1] and heard(r, 1) == [0, 2]
    assert heard(rab(line, check_occlusions=False), 0) == [1, 2]
    # the middle robot lower than the emitters (0.1 m) does not hide them
    assert heard(rab(line, heights=[H, 0.05, H]), 0) == [1, 2]
    box = static_scene(World(robots=[], obstacles=[Box(position=(0.5, 0.0), size=(0.1, 0.1))]))
    assert heard(rab([[0, 0], [1, 0]], scene=box), 0) == []
    low = static_scene(World(robots=[], obstacles=[Cylinder(position=(0.5, 0), radius_m=0.1,
                                                                      height_m=0.05)]))
    assert heard(rab([[0, 0], [1, 0]], scene=low), 0) == [1]


def test_global_mode_everyone_hears_everyone():
    xy = [[0, 0], [1, 0], [2, 0], [50, 50]]
    box = static_scene(World(robots=[], obstacles=[Box(position=(0.5, 0.0), size=(0.1, 0.1))]))
    r = rab(xy, mode="global", scene=box, ranges=0.1)
    for i in range(4):
        assert heard(r, i) == [j for j in range(4) if j != i]


def test_robots_without_the_device_neither_send_nor_receive_but_still_occlude():
    r = rab([[0, 0], [1, 0], [2, 0]], equipped=[True, False, True])
    assert heard(r, 0) == [] and heard(r, 1) == [] and heard(r, 2) == []
    r = rab([[0, 0], [1, 0], [2, 0]], equipped=[True, False, True], check_occlusions=False)
    assert heard(r, 0) == [2]


def ref_heard(xy, ranges, z, radii, heights, scene_bodies):
    """Looped reference: receiver i hears j when within j's range (3D) and no third robot or
    static body crosses the segment below its height."""
    n = len(xy)
    out = {i: [] for i in range(n)}
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            p0 = (xy[i][0], xy[i][1], z[i])
            p1 = (xy[j][0], xy[j][1], z[j])
            if math.dist(p0, p1) >= ranges[j]:
                continue
            blocked = False
            for k in range(n):
                if k in (i, j):
                    continue
                span = ref_span_circle(p0, p1, xy[k], radii[k])
                if span and min(p0[2] + t * (p1[2] - p0[2]) for t in span) < heights[k]:
                    blocked = True
            for kind, args, height in scene_bodies:
                span = ref_span_circle(p0, p1, *args) if kind == "cyl" else ref_span_box(p0, p1, *args)
                if span and min(p0[2] + t * (p1[2] - p0[2]) for t in span) < height:
                    blocked = True
            if not blocked:
                out[i].append(j)
    return out


@pytest.mark.parametrize("seed", range(4))
def test_local_mode_matches_the_looped_reference_on_random_worlds(seed):
    rng = np.random.default_rng(seed)
    n = 40
    xy = rng.uniform(-3, 3, (n, 2))
    ranges = rng.uniform(0.5, 4.0, n)
    z = rng.choice([Z, EPUCK.range_and_bearing.elevation_m], n)
    radii = rng.choice([R, EPUCK.body_radius_m], n)
    heights = rng.choice([H, 0.05, 0.09], n)
    obstacles = [Box(position=(0.0, 0.0), size=(0.6, 0.2), yaw_rad=0.4, height_m=0.5),
                 Cylinder(position=(1.5, -1.0), radius_m=0.3, height_m=0.08)]
    scene = static_scene(World(robots=[], obstacles=obstacles))
    bodies = [("box", ((0.0, 0.0), (0.6, 0.2), 0.4), 0.5), ("cyl", ((1.5, -1.0), 0.3), 0.08)]
    got = range_and_bearing(xy, rng.uniform(-3, 3, n), radii, heights, np.ones(n, bool), z, ranges,
                            np.zeros((n, 2), np.uint8), scene)
    expect = ref_heard(xy.tolist(), ranges, z, radii, heights, bodies)
    assert sum(map(len, expect.values())) > 50          # the worlds do exercise communication
    for i in range(n):
        assert heard(got, i) == expect[i]


def test_packet_drop_is_bernoulli_per_message():
    rng = np.random.default_rng(3)
    xy = np.random.default_rng(0).uniform(-1, 1, (30, 2))
    total = kept = 0
    for _ in range(50):
        r = rab(xy, mode="global", drop_probability=np.full(30, 0.3), rng=rng)
        total += 30 * 29
        kept += len(r.senders)
    assert kept / total == pytest.approx(0.7, abs=0.01)   # 43,500 draws: σ ≈ 0.002


def test_position_noise_is_a_gaussian_length_at_uniform_inclination_and_azimuth():
    rng = np.random.default_rng(4)
    sigma = 0.05
    xy = np.array([[0.0, 0.0], [1.0, 0.0]])
    v = []
    for _ in range(4000):
        r = rab(xy, mode="global", noise_std_m=np.full(2, sigma), rng=rng)
        _, rng_m, hb, vb, _ = r.of(0)
        v.append([rng_m[0] * math.cos(vb[0]) * math.cos(hb[0]), rng_m[0] * math.cos(vb[0]) * math.sin(hb[0]),
                  rng_m[0] * math.sin(vb[0])])
    noise = np.array(v) - [1.0, 0.0, 0.0]
    np.testing.assert_allclose(noise.mean(axis=0), 0.0, atol=0.003)
    # N(0, σ) length: E|v|² = σ². ARGoS draws the inclination uniformly in [0, π] (not uniform
    # on the sphere), so E[cos² θ] = 1/2 goes to z and 1/4 to each of x and y.
    assert (noise ** 2).sum(axis=1).mean() == pytest.approx(sigma ** 2, rel=0.05)
    np.testing.assert_allclose((noise ** 2).mean(axis=0), [sigma ** 2 / 4, sigma ** 2 / 4, sigma ** 2 / 2],
                               rtol=0.1)
    with pytest.raises(ValueError, match="rng"):
        rab(xy, noise_std_m=np.full(2, sigma))
