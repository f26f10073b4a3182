"""Angles and pose arrays (devices/common/poses.py)."""
import math

import numpy as np
import pytest

from composed_sim.devices.common.poses import checked_poses, wrap_angle


def test_wrap_angle_half_open_interval():
    a = np.array([math.pi, -math.pi, 3 * math.pi, 0.0, -0.5, 7.0, -7.0])
    np.testing.assert_allclose(wrap_angle(a), [math.pi, math.pi, math.pi, 0.0, -0.5, 7.0 - 2 * math.pi,
                                               -7.0 + 2 * math.pi], atol=1e-12)


def test_an_angle_in_range_comes_back_bit_for_bit():
    a = np.random.default_rng(1).uniform(-math.pi, math.pi, 10_000)
    assert np.array_equal(wrap_angle(a), a)
    assert np.all((wrap_angle(a * 50) > -math.pi) & (wrap_angle(a * 50) <= math.pi))


def test_checked_poses_names_the_wrong_shape():
    p, h = checked_poses(2, [[0, 1], [2, 3]], [0, 1])
    assert p.dtype == float and p.shape == (2, 2) and h.shape == (2,)
    with pytest.raises(ValueError, match=r"positions must be \[2, 2\] \(a row per robot\), got shape \(3, 2\)"):
        checked_poses(2, np.zeros((3, 2)), [0, 1])
    with pytest.raises(ValueError, match=r"headings must be \[2\] \(one per robot\), got shape \(2, 1\)"):
        checked_poses(2, np.zeros((2, 2)), np.zeros((2, 1)))
