"""The device plugins' pure functions, without ROS."""
import math

import numpy as np
import pytest

from composed_sim.world.robot_models import EPUCK, FOOTBOT, TURTLEBOT3_BURGER
from controller_plugins.diffusion import diffusion_wheels, obstacle_vector
from controller_plugins.firefly import advance
from controller_plugins.turtlebot_flocking import goal_vector, scan_samples

RING = np.asarray(FOOTBOT.proximity.angles_rad)


def test_diffusion_goes_straight_when_free_and_turns_away_from_an_obstacle():
    free = np.zeros(24)
    assert diffusion_wheels(free, RING, math.radians(7.5), 0.1, 0.1) == (0.1, 0.1)
    left = free.copy()
    left[5] = 0.8                                  # 82.5°: obstacle on the left
    assert obstacle_vector(left, RING)[0] == pytest.approx(RING[5])
    assert diffusion_wheels(left, RING, math.radians(7.5), 0.1, 0.1) == (0.1, 0.0)     # turn right
    right = free.copy()
    right[20] = 0.8
    assert diffusion_wheels(right, RING, math.radians(7.5), 0.1, 0.1) == (0.0, 0.1)    # turn left
    ahead = np.zeros(8)
    ahead[[0, 7]] = 0.3                            # e-puck: symmetric about the front, weak
    assert diffusion_wheels(ahead, np.asarray(EPUCK.proximity.angles_rad), math.radians(7.5), 0.1, 0.1) == (0.1, 0.1)


def test_firefly_phase_advances_flashes_at_one_and_is_pulled_by_a_flash():
    assert advance(0.5, 0.05, False, 0.2) == (pytest.approx(0.55), False)
    assert advance(0.5, 0.05, True, 0.2) == (pytest.approx(0.66), False)     # 0.55 + 0.2 · 0.55
    assert advance(0.96, 0.05, False, 0.2) == (0.0, True)
    assert advance(0.85, 0.05, True, 0.2) == (0.0, True)                   # absorbed: 0.9 · 1.2 ≥ 1
    assert advance(0.0, 0.05, True, 0.0) == (pytest.approx(0.05), False)   # uncoupled: deaf


def test_lidar_hits_move_from_the_mount_to_base_link():
    lidar = TURTLEBOT3_BURGER.lidar
    ranges = np.full(lidar.n_rays, np.inf)
    ranges[0] = 1.0                                 # straight ahead of the scanner
    ranges[180] = 1.0                               # straight behind it
    bearings, distances = scan_samples(ranges, lidar.angles_array(), np.asarray(lidar.mount_m[:2]))
    np.testing.assert_allclose(distances, [1.0 - 0.064, 1.0 + 0.064], atol=1e-9)
    np.testing.assert_allclose(np.abs(bearings), [0.0, math.pi], atol=1e-9)


def test_goal_vector_is_in_the_robot_frame_with_the_given_length():
    np.testing.assert_allclose(goal_vector(np.array([0.0, 0.0, math.pi / 2]), np.array([0.0, 5.0]), 2.0), [2.0, 0.0],
                               atol=1e-12)     # facing the goal: straight ahead
    np.testing.assert_allclose(goal_vector(np.array([1.0, 0.0, 0.0]), np.array([1.0, -3.0]), 1.0), [0.0, -1.0],
                               atol=1e-12)     # goal to the right
    assert not goal_vector(np.array([1.0, 2.0, 0.3]), np.array([1.0, 2.0]), 1.0).any()


def test_diffusion_turns_when_the_obstacle_ahead_is_close():
    ahead = np.zeros(8)
    ahead[[0, 7]] = 0.5                            # the mean vector is longer than delta: too close
    left, right = diffusion_wheels(ahead, np.asarray(EPUCK.proximity.angles_rad), math.radians(7.5), 0.1, 0.1)
    assert left != right


def test_turning_on_the_spot_ignores_what_is_only_behind():
    behind = np.zeros(24)
    behind[12] = 0.9                                 # 187.5°
    assert diffusion_wheels(behind, RING, math.radians(7.5), 0.1, 0.1) == (0.0, 0.1)          # ARGoS turns
    assert diffusion_wheels(behind, RING, math.radians(7.5), 0.1, 0.1, on_the_spot=True) == (0.1, 0.1)
    left = np.zeros(24)
    left[3] = 0.9                                    # 52.5°: turn right in place
    assert diffusion_wheels(left, RING, math.radians(7.5), 0.1, 0.1, on_the_spot=True) == (0.1, -0.1)
