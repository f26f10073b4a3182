"""The wheels' own devices: actuator noise, the differential steering sensor, odometry, and
the positioning sensor (ground truth). All per robot arrays; cheap, so always on.

ARGoS (docs/architecture.md, "Differential steering and positioning"):
- actuator noise per wheel: speed · f + bias, with a per-robot, per-wheel constant bias
  ~ N(bias_mean, bias_std) drawn once and a factor ~ N(factor_mean, factor_std) drawn per
  command, only where the speed is non-zero;
- the sensor reports the wheel speeds the actuator applied (after its noise) and the distance
  each wheel covered in the tick (speed · tick), with optional uniform noise on each
  (``differential_steering_default_sensor.cpp``: vel_noise_range, dist_noise_range);
- positioning: the true pose, with optional uniform noise on the position and on the yaw.
Odometry integrates the sensor's wheel distances from the robot's start (the ``odom`` frame:
the start pose is the identity), so it drifts from the truth through the sensor noise and
whatever the physics did that the wheels do not show (collisions, pushing).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from composed_sim.devices.common.noise import NoiseStream
from composed_sim.devices.common.poses import wrap_angle


@dataclass(frozen=True)
class WheelNoise:
    """Actuator noise per robot, m/s; all zero (the default) means exact wheels."""
    bias_mean_mps: np.ndarray    # [n]
    bias_std_mps: np.ndarray     # [n]
    factor_mean: np.ndarray      # [n]
    factor_std: np.ndarray       # [n]

    @property
    def is_exact(self) -> bool:
        return not (self.bias_mean_mps.any() or self.bias_std_mps.any() or self.factor_std.any()
                    or (self.factor_mean != 1.0).any())


class WheelActuator:
    """Turns commanded wheel speeds into applied ones with the ARGoS noise model."""

    def __init__(self, noise: WheelNoise, rng):
        """``rng``: a Generator, or a NoiseStream (devices/common/noise.py: draws per robot and tick)."""
        self.noise = noise
        self._rng = rng
        n = len(noise.bias_mean_mps)
        # Drawn once per robot and wheel, whether or not it ever moves (ARGoS: at Init).
        self.bias_mps = (self._draws(-1, n).normal(0.0, 1.0, (n, 2)) * noise.bias_std_mps[:, None]
                         + noise.bias_mean_mps[:, None]) if not noise.is_exact else np.zeros((n, 2))

    def _draws(self, tick: int, n: int):
        return self._rng.at(tick, np.arange(n)) if isinstance(self._rng, NoiseStream) else self._rng

    def apply(self, left_mps: np.ndarray, right_mps: np.ndarray, tick: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """[n] commanded → [n] applied speeds (the command itself when the noise is off), for the
        step after ``tick``."""
        if self.noise.is_exact:
            return left_mps, right_mps
        speeds = np.column_stack([left_mps, right_mps])                       # [n, 2]
        factor = (self._draws(tick, len(speeds)).normal(0.0, 1.0, speeds.shape) * self.noise.factor_std[:, None]
                  + self.noise.factor_mean[:, None])
        noisy = np.where(speeds != 0.0, speeds * factor + self.bias_mps, 0.0)
        return noisy[:, 0].copy(), noisy[:, 1].copy()


@dataclass
class WheelReadings:
    """The differential steering sensor of every robot for one tick."""
    velocities_mps: np.ndarray   # [n, 2] (left, right) applied wheel speeds
    distances_m: np.ndarray      # [n, 2] (left, right) distance each wheel covered this tick
    axis_length_m: np.ndarray    # [n] wheel separation


def differential_steering(left_mps: np.ndarray, right_mps: np.ndarray, tick_s: float,
                          axis_length_m: np.ndarray, *, velocity_noise_mps: Optional[np.ndarray] = None,
                          distance_noise_m: Optional[np.ndarray] = None,
                          rng: Optional[np.random.Generator] = None) -> WheelReadings:
    """Applied speeds [n] each → readings; noise: uniform(-a, a) per robot [n] (None: none)."""
    velocities = np.column_stack([left_mps, right_mps]).astype(np.float64)
    distances = velocities * tick_s
    if velocity_noise_mps is not None and velocity_noise_mps.any():
        velocities = velocities + rng.uniform(-1.0, 1.0, velocities.shape) * velocity_noise_mps[:, None]
    if distance_noise_m is not None and distance_noise_m.any():
        distances = distances + rng.uniform(-1.0, 1.0, distances.shape) * distance_noise_m[:, None]
    return WheelReadings(velocities, distances, np.asarray(axis_length_m, dtype=np.float64))


class Odometry:
    """Dead reckoning from the wheel distances, in each robot's ``odom`` frame."""

    def __init__(self, n: int):
        self.pose = np.zeros((n, 3))   # [n, 3] x, y, yaw in the odom frame; the start is the identity

    def update(self, wheels: WheelReadings) -> None:
        dl, dr = wheels.distances_m[:, 0], wheels.distances_m[:, 1]
        ds = 0.5 * (dl + dr)
        dyaw = (dr - dl) / wheels.axis_length_m
        yaw = self.pose[:, 2]
        # Along the heading at the start of the tick: the dynamics2d drive moves the body along
        # exactly that direction for the whole tick (core/physics.py), so in free space with
        # exact wheels the odometry follows the true motion.
        self.pose[:, 0] += ds * np.cos(yaw)
        self.pose[:, 1] += ds * np.sin(yaw)
        self.pose[:, 2] = wrap_angle(yaw + dyaw)

    def twist(self, wheels: WheelReadings) -> np.ndarray:
        """[n, 2] (linear m/s, angular rad/s) in the body frame, from the wheel speeds."""
        vl, vr = wheels.velocities_mps[:, 0], wheels.velocities_mps[:, 1]
        return np.column_stack([0.5 * (vl + vr), (vr - vl) / wheels.axis_length_m])


@dataclass
class PoseReadings:
    """The positioning sensor of every robot: the world-frame pose."""
    positions: np.ndarray      # [n, 3] m (z = 0: the robots stand on the floor)
    yaws: np.ndarray           # [n] rad, (-pi, pi]
    quaternions: np.ndarray    # [n, 4] (x, y, z, w), rotation about z by the yaw


def positioning(positions: np.ndarray, headings: np.ndarray, *,
                position_noise_m: Optional[np.ndarray] = None, yaw_noise_rad: Optional[np.ndarray] = None,
                rng: Optional[np.random.Generator] = None, altitudes: Optional[np.ndarray] = None) -> PoseReadings:
    """positions [n, 2], headings [n] (and altitudes [n], None: on the floor) → readings; noise:
    uniform(-a, a) per robot [n] on x and y and on the yaw (None: none)."""
    n = len(positions)
    xyz = np.column_stack([positions, np.zeros(n) if altitudes is None else altitudes])
    yaw = np.asarray(headings, dtype=np.float64)
    if position_noise_m is not None and position_noise_m.any():
        xyz[:, :2] += rng.uniform(-1.0, 1.0, (n, 2)) * position_noise_m[:, None]
    if yaw_noise_rad is not None and yaw_noise_rad.any():
        yaw = wrap_angle(yaw + rng.uniform(-1.0, 1.0, n) * yaw_noise_rad)
    half = 0.5 * yaw
    quat = np.column_stack([np.zeros(n), np.zeros(n), np.sin(half), np.cos(half)])
    return PoseReadings(xyz, yaw, quat)
