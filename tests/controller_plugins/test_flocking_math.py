"""The flocking controller's pure parts against the ARGoS reference values (no ROS traffic)."""
import math

import numpy as np
import pytest

from controller_plugins.flocking import (INTERACTION_RANGE, Turn, TurningMachine, flocking_vector,
                                         lennard_jones, light_vector)

TARGET, GAIN, EXP, MAX = 75.0, 1000.0, 2.0, 10.0   # the experiments' parameters, cm and cm/s


@pytest.mark.parametrize("d, expected", [(50.0, -56.25), (75.0, 0.0), (100.0, 2.4609375)])
def test_lennard_jones_reference_values(d, expected):
    assert lennard_jones(d, TARGET, GAIN, EXP) == pytest.approx(expected, abs=1e-9)


def test_lennard_jones_sign_repulsive_below_attractive_above():
    d = np.linspace(20, 200, 50)
    f = lennard_jones(d, TARGET, GAIN, EXP)
    assert np.all(f[d < TARGET] < 0) and np.all(f[d > TARGET] > 0)


def test_flocking_vector_averages_and_ignores_far_blobs():
    # One blob straight ahead at 50 cm (repulsive: pushes backwards) and one far away (ignored).
    far = INTERACTION_RANGE * TARGET + 1
    v = flocking_vector(np.array([0.0, 1.0]), np.array([50.0, far]), TARGET, GAIN, EXP, MAX)
    # |f(50)| = 56.25 > max speed 10 → clamped to 10, pointing backwards.
    np.testing.assert_allclose(v, [-MAX, 0.0], atol=1e-9)
    two = flocking_vector(np.array([math.pi / 2, -math.pi / 2]), np.array([100.0, 100.0]),
                          TARGET, GAIN, EXP, MAX)
    np.testing.assert_allclose(two, [0.0, 0.0], atol=1e-12)     # symmetric pulls cancel
    one = flocking_vector(np.array([math.pi / 2]), np.array([100.0]), TARGET, GAIN, EXP, MAX)
    np.testing.assert_allclose(one, [0.0, 2.4609375], atol=1e-9)   # below the clamp: unchanged
    assert not flocking_vector(np.array([]), np.array([]), TARGET, GAIN, EXP, MAX).any()


def test_light_vector_is_quarter_max_speed_towards_the_light():
    angles = np.radians(7.5 + 15 * np.arange(24))
    readings = np.zeros(24)
    readings[5] = 0.8                     # sensor 5 at 82.5°
    v = light_vector(readings, angles, MAX)
    assert math.hypot(*v) == pytest.approx(0.25 * MAX)
    assert math.atan2(v[1], v[0]) == pytest.approx(math.radians(82.5))
    assert not light_vector(np.zeros(24), angles, MAX).any()


def machine(state=Turn.NO_TURN):
    return TurningMachine(MAX, math.radians(90), math.radians(70), math.radians(10), state)


def polar(length, deg):
    return np.array([length * math.cos(math.radians(deg)), length * math.sin(math.radians(deg))])


def test_no_turn_drives_straight_at_the_heading_length_capped():
    m = machine()
    assert m.wheel_speeds(polar(4.0, 5)) == pytest.approx((4.0, 4.0))
    assert m.wheel_speeds(polar(25.0, -5)) == pytest.approx((MAX, MAX))
    assert m.state is Turn.NO_TURN


def test_soft_turn_speeds_and_side():
    m = machine()
    f = (90 - 30) / 90
    assert m.wheel_speeds(polar(6.0, 30)) == pytest.approx((6.0 * f, 6.0 * (2 - f)))   # left turn: right faster
    assert m.state is Turn.SOFT_TURN
    assert m.wheel_speeds(polar(6.0, -30)) == pytest.approx((6.0 * (2 - f), 6.0 * f))  # right turn


def test_hard_turn_spins_in_place_at_max_speed():
    m = machine()
    assert m.wheel_speeds(polar(1.0, 120)) == pytest.approx((-MAX, MAX))
    assert m.state is Turn.HARD_TURN
    assert m.wheel_speeds(polar(1.0, -120)) == pytest.approx((MAX, -MAX))


def test_hysteresis_and_cascades():
    m = machine(Turn.HARD_TURN)
    m.wheel_speeds(polar(5.0, 80))           # between soft (70) and hard (90): stays hard
    assert m.state is Turn.HARD_TURN
    m.wheel_speeds(polar(5.0, 60))           # ≤ soft: hard → soft
    assert m.state is Turn.SOFT_TURN
    m = machine(Turn.HARD_TURN)
    assert m.wheel_speeds(polar(5.0, 5)) == pytest.approx((5.0, 5.0))   # hard → soft → no in one call
    assert m.state is Turn.NO_TURN
    m = machine(Turn.SOFT_TURN)
    m.wheel_speeds(polar(5.0, 95))           # soft → hard
    assert m.state is Turn.HARD_TURN
