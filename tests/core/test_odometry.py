"""Wheel actuator noise, the differential steering sensor, odometry and positioning."""
from __future__ import annotations

import math

import numpy as np
import pytest

from composed_sim.core.odometry import (Odometry, WheelActuator, WheelNoise, differential_steering,
                                        positioning)
from composed_sim.core.simulation import Simulation
from composed_sim.world.schema import World


def noise(n, bias_mean=0.0, bias_std=0.0, factor_mean=1.0, factor_std=0.0):
    return WheelNoise(*(np.full(n, v, dtype=float) for v in (bias_mean, bias_std, factor_mean, factor_std)))


def test_exact_wheels_pass_commands_through_without_drawing():
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    act = WheelActuator(noise(3), rng)
    left, right = np.array([0.1, 0.0, -0.05]), np.array([0.1, 0.02, 0.0])
    out = act.apply(left, right)
    assert out[0] is left and out[1] is right and rng.bit_generator.state == state


def test_bias_is_drawn_once_per_robot_and_wheel_and_only_moving_wheels_get_noise():
    n = 20000
    act = WheelActuator(noise(n, bias_mean=0.01, bias_std=0.002), np.random.default_rng(1))
    assert act.bias_mps.shape == (n, 2)
    assert act.bias_mps.mean() == pytest.approx(0.01, abs=5e-5)
    assert act.bias_mps.std() == pytest.approx(0.002, rel=0.02)
    speed = np.full(n, 0.1)
    first = act.apply(speed, np.zeros(n))
    second = act.apply(speed, np.zeros(n))
    # factor_std 0: speed · 1 + the same bias each time; a wheel at 0 stays at 0 (ARGoS)
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_allclose(first[0], 0.1 + act.bias_mps[:, 0])
    assert not first[1].any()


def test_factor_is_drawn_per_command():
    n = 20000
    act = WheelActuator(noise(n, factor_mean=1.0, factor_std=0.1), np.random.default_rng(2))
    a = act.apply(np.full(n, 0.2), np.full(n, -0.1))
    b = act.apply(np.full(n, 0.2), np.full(n, -0.1))
    assert not np.array_equal(a[0], b[0])
    assert (a[0] / 0.2).mean() == pytest.approx(1.0, abs=0.003)
    assert (a[0] / 0.2).std() == pytest.approx(0.1, rel=0.03)
    assert (a[1] / -0.1).std() == pytest.approx(0.1, rel=0.03)


def test_sensor_reports_speeds_and_distances_per_tick_with_uniform_noise():
    w = differential_steering(np.array([0.1, -0.05]), np.array([0.05, 0.0]), 0.1, np.array([0.14, 0.053]))
    np.testing.assert_allclose(w.velocities_mps, [[0.1, 0.05], [-0.05, 0.0]])
    np.testing.assert_allclose(w.distances_m, [[0.01, 0.005], [-0.005, 0.0]])
    n = 20000
    w = differential_steering(np.full(n, 0.1), np.full(n, 0.1), 0.1, np.full(n, 0.14),
                              velocity_noise_mps=np.full(n, 0.01), distance_noise_m=np.full(n, 0.002),
                              rng=np.random.default_rng(3))
    dv, dd = w.velocities_mps - 0.1, w.distances_m - 0.01
    assert np.abs(dv).max() <= 0.01 and dv.var() == pytest.approx(0.01 ** 2 / 3, rel=0.05)
    assert np.abs(dd).max() <= 0.002 and dd.var() == pytest.approx(0.002 ** 2 / 3, rel=0.05)


def test_odometry_integrates_the_wheel_distances():
    odo = Odometry(1)
    L, tick = 0.14, 0.1
    # a quarter turn in place, then 1 m straight: ends at (0, 1) facing +y
    w_turn = differential_steering(np.array([-L * math.pi / 4 / tick / 10]), np.array([L * math.pi / 4 / tick / 10]),
                                   tick, np.array([L]))
    for _ in range(10):
        odo.update(w_turn)
    np.testing.assert_allclose(odo.pose[0], [0, 0, math.pi / 2], atol=1e-12)
    straight = differential_steering(np.array([0.1]), np.array([0.1]), tick, np.array([L]))
    for _ in range(100):
        odo.update(straight)
    np.testing.assert_allclose(odo.pose[0], [0, 1, math.pi / 2], atol=1e-9)
    np.testing.assert_allclose(odo.twist(straight), [[0.1, 0.0]])


def test_positioning_pose_quaternion_and_noise():
    p = positioning(np.array([[1.0, 2.0]]), np.array([math.pi / 2]))
    np.testing.assert_allclose(p.positions, [[1, 2, 0]])
    np.testing.assert_allclose(p.quaternions, [[0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)]])
    n = 20000
    q = positioning(np.zeros((n, 2)), np.zeros(n), position_noise_m=np.full(n, 0.02),
                    yaw_noise_rad=np.full(n, 0.1), rng=np.random.default_rng(4))
    assert np.abs(q.positions[:, :2]).max() <= 0.02 and np.abs(q.yaws).max() <= 0.1
    assert q.positions[:, :2].var() == pytest.approx(0.02 ** 2 / 3, rel=0.05)
    np.testing.assert_allclose(q.quaternions[:, 2], np.sin(q.yaws / 2))


def walled_world(heading=0.3, **devices):
    return World(arena=dict(size=(3, 3), walls=True), robots=[dict(
        count=1, controller="x", placement=dict(method="explicit", positions=[(0.0, 0.0)]),
        heading=dict(method="constant", value_rad=heading), devices=devices)])


def odom_to_world(sim, odom):
    """The odom frame is the start pose: rotate and shift back to the world frame."""
    c, s = math.cos(sim.initial_headings[0]), math.sin(sim.initial_headings[0])
    x, y, yaw = odom
    return (sim.initial_positions[0][0] + c * x - s * y, sim.initial_positions[0][1] + s * x + c * y,
            yaw + sim.initial_headings[0])


def test_simulated_odometry_starts_at_identity_and_follows_free_motion():
    sim = Simulation(walled_world())
    frame = sim.sense()
    np.testing.assert_array_equal(frame.odometry, [[0, 0, 0]])
    for _ in range(30):
        sim.set_velocity_commands(np.array([0.08]), np.array([0.3]))
        frame = sim.step()
    x, y, yaw = odom_to_world(sim, frame.odometry[0])
    # the physics lags a command by about a sub-step (core/physics.py): a few mm over 30 ticks
    assert math.hypot(x - sim.positions[0, 0], y - sim.positions[0, 1]) < 0.005
    assert abs(math.remainder(yaw - sim.headings[0], 2 * math.pi)) < 0.02
    np.testing.assert_allclose(frame.wheels.velocities_mps[0], [0.08 - 0.3 * 0.07, 0.08 + 0.3 * 0.07])
    np.testing.assert_allclose(frame.pose.positions[0, :2], sim.positions[0])


def test_odometry_drifts_when_the_robot_is_stuck_against_a_wall():
    sim = Simulation(walled_world(heading=0.0))
    for _ in range(300):                   # 3 m at 0.1 m/s, straight at the +x wall
        sim.set_velocity_commands(np.array([0.1]), np.array([0.0]))
        frame = sim.step()
    assert frame.odometry[0, 0] == pytest.approx(3.0, rel=1e-6)   # the wheels turned all along
    # the wall's inner face is at 1.5 - 0.1 m: the robot stopped with its rim there
    assert sim.positions[0, 0] == pytest.approx(1.4 - sim.radii[0], abs=0.01)


def test_wheel_noise_moves_the_robot_off_the_commanded_path():
    exact = Simulation(walled_world())
    noisy = Simulation(walled_world(wheels=dict(bias_std_mps=0.01, factor_std=0.1)))
    for sim in (exact, noisy):
        for _ in range(20):
            sim.set_velocity_commands(np.array([0.05]), np.array([0.0]))
            sim.step()
    assert np.abs(noisy.positions - exact.positions).max() > 1e-3
    again = Simulation(walled_world(wheels=dict(bias_std_mps=0.01, factor_std=0.1)))
    for _ in range(20):
        again.set_velocity_commands(np.array([0.05]), np.array([0.0]))
        again.step()
    np.testing.assert_array_equal(again.positions, noisy.positions)     # one seed fixes the noise
