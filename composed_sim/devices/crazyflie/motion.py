"""How the drones move under their setpoints, per tick, in arrays.

By default a drone is where its setpoint says (Crazyswarm2's ``none`` simulation backend: the
controller tracks perfectly): a high-level, full-state or position setpoint sets its position,
velocity and yaw; a hover setpoint holds the height and integrates the body-frame velocities and
the yaw rate; a world velocity integrates; an attitude setpoint (roll, pitch, yaw rate, thrust)
accelerates a point mass by the motors' thrust along the tilted body axis against gravity.
Motors off (idle, stopped, landed, locked) the drone falls freely, keeping its horizontal speed,
until the floor (z = 0) stops it; it stays there. Level-out holds x, y and yaw.

``Tracking`` optionally replaces the perfect tracking of the position setpoints by a lag:
first order (each coordinate and yaw approach the setpoint with time constant ``time_constant_s``)
or second order (a critically damped spring of natural frequency ``1 / time_constant_s``, the
setpoint's velocity as feed-forward).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from composed_sim.devices.crazyflie.commander import (ATTITUDE, FULL_STATE, HIGH_LEVEL, HOVER, LEVEL_OUT, OFF,
                                                      POSITION, VELOCITY, Setpoints)
from composed_sim.devices.crazyflie.polynomials import GRAVITY_MPS2, normalize_radians

# The thrust of one motor (N) against its PWM command (0-65535): Crazyswarm2's system
# identification of the Crazyflie 2.1's motors and propellers, a quadratic in grams.
_PWM_TO_GRAMS = (1.71479058e-09, 8.80284482e-05, -2.21152097e-01)


def thrust_newtons(pwm: np.ndarray) -> np.ndarray:
    """The four motors' total thrust (N) at a legacy thrust command, every motor at it."""
    grams = np.polyval(_PWM_TO_GRAMS, pwm)
    return 4.0 * np.maximum(grams, 0.0) * GRAVITY_MPS2 / 1000.0


@dataclass(frozen=True)
class Tracking:
    order: int                 # 1 or 2
    time_constant_s: float

    def __post_init__(self):
        if self.order not in (1, 2) or not self.time_constant_s > 0:
            raise ValueError(f"tracking: order 1 or 2 and a positive time constant, got {self}")


class DroneState:
    """Position, velocity [n, 3] and yaw [n] of every drone."""

    def __init__(self, pos, yaw):
        self.pos = np.array(pos, dtype=np.float64).reshape(-1, 3)
        self.vel = np.zeros_like(self.pos)
        self.yaw = np.array(yaw, dtype=np.float64).reshape(-1)


def advance(state: DroneState, sp: Setpoints, dt: float, mass_kg: float,
            tracking: Optional[Tracking] = None) -> None:
    """Move every drone by one tick of ``dt`` s under its setpoint (in place)."""
    kind = sp.kind
    exact = (kind == HIGH_LEVEL) | (kind == FULL_STATE) | (kind == POSITION)
    if exact.any():
        _track(state, sp, np.flatnonzero(exact), dt, tracking)
    for k, move in ((HOVER, _hover), (VELOCITY, _velocity), (LEVEL_OUT, _level_out),
                    (ATTITUDE, _attitude), (OFF, _fall)):
        rows = np.flatnonzero(kind == k)
        if len(rows):
            move(state, sp, rows, dt, mass_kg)
    below = state.pos[:, 2] < 0.0
    state.pos[below, 2] = 0.0
    state.vel[below] = 0.0
    state.yaw[:] = normalize_radians(state.yaw)


def _track(state, sp, rows, dt, tracking) -> None:
    if tracking is None:
        state.pos[rows], state.vel[rows], state.yaw[rows] = sp.pos[rows], sp.vel[rows], sp.yaw[rows]
        return
    k = dt / tracking.time_constant_s
    yaw_error = normalize_radians(sp.yaw[rows] - state.yaw[rows])
    if tracking.order == 1:
        gain = 1.0 - np.exp(-k)
        new = state.pos[rows] + gain * (sp.pos[rows] - state.pos[rows])
        state.vel[rows] = (new - state.pos[rows]) / dt
        state.pos[rows] = new
        state.yaw[rows] += gain * yaw_error
        return
    w = 1.0 / tracking.time_constant_s     # critically damped: x'' = w² (x* - x) + 2 w (v* - v)
    acc = w * w * (sp.pos[rows] - state.pos[rows]) + 2.0 * w * (sp.vel[rows] - state.vel[rows])
    state.vel[rows] += acc * dt
    state.pos[rows] += state.vel[rows] * dt
    state.yaw[rows] += (1.0 - np.exp(-k)) * yaw_error


def _hover(state, sp, rows, dt, mass_kg) -> None:
    c, s = np.cos(state.yaw[rows]), np.sin(state.yaw[rows])
    vx, vy = sp.vel[rows, 0], sp.vel[rows, 1]
    world = np.column_stack([c * vx - s * vy, s * vx + c * vy])
    z0 = state.pos[rows, 2]
    state.pos[rows, :2] += world * dt
    state.pos[rows, 2] = sp.pos[rows, 2]
    state.vel[rows] = np.column_stack([world, (sp.pos[rows, 2] - z0) / dt])
    state.yaw[rows] += sp.yaw_rate[rows] * dt


def _velocity(state, sp, rows, dt, mass_kg) -> None:
    state.vel[rows] = sp.vel[rows]
    state.pos[rows] += sp.vel[rows] * dt
    state.yaw[rows] += sp.yaw_rate[rows] * dt


def _level_out(state, sp, rows, dt, mass_kg) -> None:
    z0 = state.pos[rows, 2]
    target = sp.pos[rows, 2]
    z = np.where(np.isnan(target), z0 + sp.vel[rows, 2] * dt, target)
    state.pos[rows, 2] = z
    state.vel[rows] = np.column_stack([np.zeros((len(rows), 2)), (z - z0) / dt])


def _attitude(state, sp, rows, dt, mass_kg) -> None:
    roll, pitch, yaw = sp.roll[rows], sp.pitch[rows], state.yaw[rows]
    cr, sr, cp, spch, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    # The body z axis of roll-pitch-yaw (ZYX) angles, in the world frame.
    z_body = np.column_stack([cy * spch * cr + sy * sr, sy * spch * cr - cy * sr, cp * cr])
    acc = z_body * (thrust_newtons(sp.thrust[rows]) / mass_kg)[:, None]
    acc[:, 2] -= GRAVITY_MPS2
    on_floor = (state.pos[rows, 2] <= 0.0) & (acc[:, 2] <= 0.0)
    acc[on_floor] = 0.0
    state.vel[rows[on_floor]] = 0.0
    state.vel[rows] += acc * dt
    state.pos[rows] += state.vel[rows] * dt
    state.yaw[rows] += sp.yaw_rate[rows] * dt


def _fall(state, sp, rows, dt, mass_kg) -> None:
    airborne = rows[state.pos[rows, 2] > 0.0]
    grounded = rows[state.pos[rows, 2] <= 0.0]
    state.vel[grounded] = 0.0
    state.vel[airborne, 2] -= GRAVITY_MPS2 * dt
    state.pos[airborne] += state.vel[airborne] * dt
