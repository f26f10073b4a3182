"""The ray/segment kernels and the static scene, on hand-made cases and against a slow reference."""
from __future__ import annotations

import math

import numpy as np
from reference_geometry import ref_span_box, ref_span_circle
import pytest

from composed_sim.devices.common import geometry
from composed_sim.core.scene import static_scene
from composed_sim.devices.common.geometry import (StaticScene, box_corners, points_in_polygons, ray_circle_distance,
                                        ray_segment_distance, ray_segments_first_hit,
                                        segments_blocked_by_cylinders, segments_blocked_by_prisms)
from composed_sim.world.schema import Arena, Box, Cylinder, World

INF = math.inf


def v(*xs):
    return np.array(xs, dtype=float)


# --- slow, obvious references: one segment against one body, plain floats ------------------

def ref_blocked(span, p0, p1, height):
    if span is None:
        return False
    z = [p0[2] + t * (p1[2] - p0[2]) for t in span]
    return min(z) < height


# --- kernels on hand-made cases --------------------------------------------------------------

def test_ray_circle_distance():
    o, d = v(0, 0), v(1, 0)
    assert ray_circle_distance(o, d, v(2, 0), 0.5) == pytest.approx(1.5)
    assert ray_circle_distance(o, d, v(2, 0.3), 0.5) == pytest.approx(2 - math.sqrt(0.25 - 0.09))
    assert ray_circle_distance(o, d, v(2, 0.6), 0.5) == INF         # passes beside
    assert ray_circle_distance(o, d, v(-2, 0), 0.5) == INF          # behind
    assert ray_circle_distance(o, d, v(0.2, 0), 0.5) == 0.0         # starts inside
    # broadcasting: [3, 1] rays against [2] circles
    out = ray_circle_distance(np.zeros((3, 1, 2)), np.array([[[1, 0]], [[0, 1]], [[-1, 0]]], float),
                              np.array([[3, 0], [0, 2]], float), np.array([1.0, 1.0]))
    np.testing.assert_allclose(out, [[2, INF], [INF, 1], [INF, INF]])


def test_ray_segment_distance():
    o, d = v(0, 0), v(1, 0)
    assert ray_segment_distance(o, d, v(2, -1), v(2, 1)) == pytest.approx(2)
    assert ray_segment_distance(o, d, v(2, 0.1), v(2, 1)) == INF      # beside the end
    assert ray_segment_distance(o, d, v(-2, -1), v(-2, 1)) == INF     # behind
    assert ray_segment_distance(o, d, v(1, 0), v(3, 0)) == INF        # parallel (colinear): a miss
    assert ray_segment_distance(o, v(2, 0), v(1, -1), v(1, 1)) == pytest.approx(0.5)   # as a fraction


def test_ray_segments_first_hit_on_the_scene_edges():
    scene = static_scene(World(robots=[], arena=Arena(size=(4, 2), walls=True),
                                         obstacles=[Box(position=(1, 0), size=(0.2, 0.2))]))
    o = np.array([[0, 0], [0, 0], [0, 0], [1.5, 0.5]], dtype=float)
    d = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=float)
    # The walls (0.1 m thick) stand inside the arena rectangle, where the physics has them.
    np.testing.assert_allclose(ray_segments_first_hit(o, d, scene.segments), [0.9, 1.9, 0.9, 1.4])
    assert ray_segments_first_hit(o, d, np.zeros((0, 2, 2))).tolist() == [INF] * 4


def test_points_in_polygons():
    sq = box_corners((0, 0), (2, 2), 0.0)
    assert points_in_polygons(np.array([[0, 0], [0.99, -0.99], [1.01, 0], [1, 1]]), sq).tolist() == \
        [True, True, False, True]
    diamond = box_corners((0, 0), (2, 2), math.pi / 4)
    assert points_in_polygons(np.array([[0.9, 0.9], [1.3, 0]]), diamond).tolist() == [False, True]


def test_box_corners_are_counter_clockwise_and_rotated():
    c = box_corners((1, 2), (2, 1), math.pi / 2)
    np.testing.assert_allclose(c, [[1.5, 1], [1.5, 3], [0.5, 3], [0.5, 1]], atol=1e-12)
    area2 = np.sum(c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1])
    assert area2 > 0


@pytest.mark.parametrize("p0, p1, expect", [
    ((-1, 0, 0.0), (1, 0, 0.0), True),        # along the floor
    ((-1, 0, 0.6), (1, 0, 0.6), False),       # level, above the top
    ((-1, 0, 0.0), (1, 0, 1.0), True),        # ascending: enters at x = -0.2, z = 0.4
    ((-1, 0, 0.0), (1, 0, 2.0), False),       # enters at z = 0.8
    ((-2, 0, 0.0), (-0.5, 0, 0.0), False),    # ends before the disc
    ((0, 0, 0.3), (0, 0, 0.1), True),         # vertical, inside
    ((0.3, 0.3, 0.0), (0.3, 0.3, 1.0), False),  # vertical, outside
    ((-1, 0, 0.7), (0.1, 0, 0.4), True),      # descending through the top face, ends inside below h
])
def test_segment_blocked_by_cylinder(p0, p1, expect):
    # disc of radius 0.2 at the origin, height 0.5
    assert bool(segments_blocked_by_cylinders(v(*p0), v(*p1), v(0, 0), 0.2, 0.5)) == \
        ref_blocked(ref_span_circle(p0, p1, (0, 0), 0.2), p0, p1, 0.5)
    assert bool(segments_blocked_by_cylinders(v(*p0), v(*p1), v(0, 0), 0.2, 0.5)) is expect


@pytest.mark.parametrize("p0, p1, expect", [
    ((-1, 0, 0.0), (1, 0, 0.0), True),
    ((-1, 0, 0.6), (1, 0, 0.6), False),
    ((-1, 0, 0.0), (1, 0, 4.0), False),       # enters at x = -0.2, z = 1.6
    ((-1, 0, 0.0), (1, 0, 1.0), True),        # enters at z = 0.4
    ((-1, 0, 0.7), (0.1, 0, 0.4), True),      # ends inside, below the top
    ((0, 0, 0.3), (0, 0, 0.1), True),         # vertical, inside
    ((-1, 0.3, 0.0), (1, 0.3, 0.0), False),   # beside
])
def test_segment_blocked_by_prism(p0, p1, expect):
    # a 0.4 x 0.4 box at the origin, height 0.5
    poly = box_corners((0, 0), (0.4, 0.4), 0.0)
    assert bool(segments_blocked_by_prisms(v(*p0), v(*p1), poly, 0.5)) is expect


def test_blocked_kernels_match_the_slab_and_quadratic_references():
    rng = np.random.default_rng(7)
    m = 3000
    p0 = np.column_stack([rng.uniform(-1, 1, (m, 2)), rng.uniform(0, 0.6, m)])
    p1 = np.column_stack([rng.uniform(-1, 1, (m, 2)), rng.uniform(0, 0.6, m)])
    centre, size, yaw, height = (0.1, -0.05), (0.5, 0.3), 0.7, 0.35
    got = segments_blocked_by_prisms(p0, p1, box_corners(centre, size, yaw), height)
    want = [ref_blocked(ref_span_box(a, b, centre, size, yaw), a, b, height) for a, b in zip(p0, p1)]
    assert got.tolist() == want
    assert 0.1 < np.mean(want) < 0.9
    got = segments_blocked_by_cylinders(p0, p1, np.array(centre), 0.3, height)
    want = [ref_blocked(ref_span_circle(a, b, centre, 0.3), a, b, height) for a, b in zip(p0, p1)]
    assert got.tolist() == want


# --- the static scene ------------------------------------------------------------------------

def test_scene_from_world_with_walls_boxes_and_cylinders():
    world = World(robots=[], arena=Arena(center=(1, 0), size=(4, 2), walls=True, wall_thickness_m=0.1,
                                         wall_height_m=0.3),
                  obstacles=[Box(position=(0, 0), size=(0.4, 0.2), height_m=0.2, yaw_rad=0.3),
                             Cylinder(position=(1, 0.5), radius_m=0.1, height_m=0.4)])
    scene = static_scene(world)
    assert scene.box_corners.shape == (5, 4, 2) and scene.segments.shape == (20, 2, 2)
    np.testing.assert_allclose(scene.box_heights, [0.3] * 4 + [0.2])
    np.testing.assert_allclose(scene.segment_heights, [0.3] * 16 + [0.2] * 4)
    np.testing.assert_allclose(scene.cyl_centres, [[1, 0.5]])
    # walls: inside the arena rectangle [-1, 3] x [-1, 1] (outer faces on it), where the physics has them
    walls = scene.box_corners[:4]
    assert walls[:, :, 0].min() == pytest.approx(-1) and walls[:, :, 0].max() == pytest.approx(3)
    assert walls[:, :, 1].min() == pytest.approx(-1) and walls[:, :, 1].max() == pytest.approx(1)
    inside = np.array([[-0.89, 0.0], [2.89, 0.89], [1.0, -0.89]])
    assert not points_in_polygons(inside[:, None], walls).any()
    # a ray to the +x wall from the arena centre, and one that starts inside a wall
    d = scene.ray_distance(np.array([[1.0, -0.5], [2.95, -0.5]]), np.array([[1.0, 0], [1, 0]]), 5.0)
    np.testing.assert_allclose(d, [1.9, 0.0])
    with pytest.raises(ValueError, match="walls"):
        static_scene(World(robots=[], arena=Arena(walls=True)))


def test_scene_ray_distance_hits_boxes_cylinders_and_respects_height_and_range():
    scene = static_scene(World(robots=[], obstacles=[
        Box(position=(2, 0), size=(1, 1), height_m=0.5),
        Cylinder(position=(0, 2), radius_m=0.5, height_m=0.05)]))
    o = np.zeros((4, 2))
    dirs = np.array([[1, 0], [0, 1], [0, 1], [-1, 0]], dtype=float)
    np.testing.assert_allclose(scene.ray_distance(o, dirs, 3.0), [1.5, 1.5, 1.5, INF])
    # the cylinder is lower than 6 cm: invisible to a ray at that elevation
    np.testing.assert_allclose(scene.ray_distance(o, dirs, 3.0, min_height=0.06), [1.5, INF, INF, INF])
    np.testing.assert_allclose(scene.ray_distance(o, dirs, 1.4), [INF] * 4)


def test_scene_blocks_and_chunking(monkeypatch):
    world = World(robots=[], arena=Arena(size=(6, 6), walls=True), obstacles=[
        Box(position=(1, 1), size=(0.5, 0.5), height_m=0.3, yaw_rad=0.4),
        Cylinder(position=(-1, 1), radius_m=0.3, height_m=0.3)])
    scene = static_scene(world)
    rng = np.random.default_rng(3)
    m = 500
    p0 = np.column_stack([rng.uniform(-3.5, 3.5, (m, 2)), rng.uniform(0, 0.6, m)])
    p1 = np.column_stack([rng.uniform(-3.5, 3.5, (m, 2)), rng.uniform(0, 0.6, m)])
    bodies = [("box", ((0, 2.95), (6, 0.1), 0.0), 0.5), ("box", ((0, -2.95), (6, 0.1), 0.0), 0.5),
              ("box", ((2.95, 0), (0.1, 6), 0.0), 0.5), ("box", ((-2.95, 0), (0.1, 6), 0.0), 0.5),
              ("box", ((1, 1), (0.5, 0.5), 0.4), 0.3), ("cyl", ((-1, 1), 0.3), 0.3)]

    def ref(a, b):
        return any(ref_blocked(ref_span_box(a, b, *args) if kind == "box" else ref_span_circle(a, b, *args),
                               a, b, h) for kind, args, h in bodies)

    want = [ref(a, b) for a, b in zip(p0, p1)]
    assert scene.blocks(p0, p1).tolist() == want
    dirs = rng.normal(size=(m, 2))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    d_full = scene.ray_distance(p0[:, :2], dirs, 1.0)
    monkeypatch.setattr(geometry, "_CHUNK_PAIRS", 7)     # many small chunks: same answers
    assert scene.blocks(p0, p1).tolist() == want
    np.testing.assert_array_equal(scene.ray_distance(p0[:, :2], dirs, 1.0), d_full)


def test_empty_scene():
    scene = StaticScene()
    assert scene.n_bodies == 0 and scene.segments.shape == (0, 2, 2)
    assert scene.blocks(np.zeros((3, 3)), np.ones((3, 3))).tolist() == [False] * 3
    assert np.isinf(scene.ray_distance(np.zeros((2, 2)), np.array([[1.0, 0], [0, 1]]), 1.0)).all()
    with pytest.raises(ValueError, match="box_corners"):
        StaticScene(box_corners=np.zeros((2, 4, 2)), box_heights=np.zeros(1))
