"""The firmware's polynomial arithmetic, batched over drones (the first axis of every array).

A piece is 4 polynomials of degree 7 (x, y, z, yaw; coefficients in ascending degree, [..., 4, 8])
over a duration. Every function here does the firmware's operations in the firmware's order, in
float64: with the firmware compiled in double precision the results agree to the last bits
(tools/crazyflie/regenerate.py, tests/devices/crazyflie/test_firmware_curves.py).
"""
from __future__ import annotations

import math

import numpy as np

DEGREE = 7
SIZE = DEGREE + 1
GRAVITY_MPS2 = 9.81            # the firmware's flatness uses 9.81 m/s² for g


def normalize_radians(angle):
    """An angle into [-π, π] as the firmware wraps it (fmod of the angle plus a signed π)."""
    signed_pi = np.copysign(np.pi, angle)
    return np.fmod(angle + signed_pi, 2 * np.pi) - signed_pi


def shortest_signed_angle(start, goal):
    """goal - start wrapped into [-π, π), with the floored modulo the firmware uses."""
    diff = goal - start
    x = diff + np.pi
    return x - np.floor(x / (2 * np.pi)) * (2 * np.pi) - np.pi


def plan_7th_order_no_jerk(duration, x0, dx0, ddx0, xf, dxf, ddxf) -> np.ndarray:
    """The unique degree-7 polynomial with the given value, slope and curvature at both ends and
    zero jerk at both, over ``duration`` [d]; the boundary values are [d, k] → [d, k, 8].

    A non-positive duration gives the end state's quadratic (the firmware's guard)."""
    T = np.asarray(duration, dtype=np.float64)[:, None]
    out = np.zeros(np.shape(x0) + (SIZE,))
    with np.errstate(divide="ignore", invalid="ignore"):
        T2 = T * T
        T3 = T2 * T
        T4 = T3 * T
        T5 = T4 * T
        T6 = T5 * T
        T7 = T6 * T
        out[..., 0] = x0
        out[..., 1] = dx0
        out[..., 2] = ddx0 / 2
        out[..., 4] = -(5 * (14 * x0 - 14 * xf + 8 * T * dx0 + 6 * T * dxf + 2 * T2 * ddx0 - T2 * ddxf)) / (2 * T4)
        out[..., 5] = (84 * x0 - 84 * xf + 45 * T * dx0 + 39 * T * dxf + 10 * T2 * ddx0 - 7 * T2 * ddxf) / T5
        out[..., 6] = -(140 * x0 - 140 * xf + 72 * T * dx0 + 68 * T * dxf + 15 * T2 * ddx0 - 13 * T2 * ddxf) / (2 * T6)
        out[..., 7] = (2 * (10 * x0 - 10 * xf + 5 * T * dx0 + 5 * T * dxf + T2 * ddx0 - T2 * ddxf)) / T7
    degenerate = T[:, 0] <= 0.0
    if degenerate.any():
        out[degenerate] = 0.0
        out[degenerate, ..., 0] = np.broadcast_to(xf, out.shape[:-1])[degenerate]
        out[degenerate, ..., 1] = np.broadcast_to(dxf, out.shape[:-1])[degenerate]
        out[degenerate, ..., 2] = np.broadcast_to(ddxf, out.shape[:-1])[degenerate] / 2
    return out


def plan_pieces(duration, pos0, yaw0, vel0, yaw_rate0, acc0, pos1, yaw1, vel1, yaw_rate1, acc1) -> np.ndarray:
    """The firmware's one-piece plan (piecewise_plan_7th_order_no_jerk) for each drone: x, y, z from
    positions, velocities, accelerations [d, 3]; yaw from yaws and yaw rates [d] with zero yaw
    acceleration at both ends → [d, 4, 8]."""
    zero = np.zeros(len(duration))
    start = np.column_stack([pos0, yaw0]), np.column_stack([vel0, yaw_rate0]), np.column_stack([acc0, zero])
    end = np.column_stack([pos1, yaw1]), np.column_stack([vel1, yaw_rate1]), np.column_stack([acc1, zero])
    return plan_7th_order_no_jerk(duration, *start, *end)


def stretch_time(coefficients: np.ndarray, scale) -> np.ndarray:
    """Pieces [d, 4, 8] stretched to take ``scale`` [d] times longer (polystretchtime's products)."""
    recip = 1.0 / np.asarray(scale, dtype=np.float64)
    factors = np.empty((len(recip), SIZE))
    factors[:, 0] = 1.0
    power = recip.copy()
    for i in range(1, SIZE):
        factors[:, i] = power
        power = power * recip
    return coefficients * factors[:, None, :]


def reflect(coefficients: np.ndarray) -> np.ndarray:
    """p(t) → p(-t): the odd coefficients negated (polyreflect)."""
    out = coefficients.copy()
    out[..., 1::2] = -out[..., 1::2]
    return out


def _falling_factorials() -> np.ndarray:
    """[8, 4]: (p + k)! / p!, the factor of the k-th derivative's coefficient of t^p."""
    return np.array([[math.prod(range(p + 1, p + k + 1)) for k in range(4)] for p in range(SIZE)], dtype=np.float64)


_FACTORS = _falling_factorials()


def values_and_derivatives(coefficients: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Pieces [d, 4, 8] at times [d] → [d, 4 axes, 4]: value and first three derivatives, by
    Horner's rule on each (polyder, then polyval), with the drones along the arrays' last axis
    (elementwise products only: a small matrix product would call BLAS, whose threads cost more
    than they give on a busy machine)."""
    d = len(coefficients)
    powers = np.ascontiguousarray(coefficients.transpose(2, 1, 0))         # [8, 4, d]
    per_power = np.zeros((SIZE, 4, 4, d))                                  # [power, axis, derivative, drone]
    for k in range(4):
        per_power[:SIZE - k, :, k, :] = _FACTORS[:SIZE - k, k, None, None] * powers[k:]
    t = np.asarray(t, dtype=np.float64)
    x = per_power[DEGREE].copy()
    for i in range(DEGREE - 1, -1, -1):
        x *= t
        x += per_power[i]
    return x.transpose(2, 0, 1)


class Evaluation:
    """Position, velocity, acceleration, jerk [d, 3], yaw [d] and body rates [d, 3] of pieces."""

    __slots__ = ("pos", "vel", "acc", "jerk", "yaw", "omega")

    def __init__(self, pos, vel, acc, jerk, yaw, omega):
        self.pos, self.vel, self.acc, self.jerk, self.yaw, self.omega = pos, vel, acc, jerk, yaw, omega


def evaluate(coefficients: np.ndarray, t: np.ndarray) -> Evaluation:
    """poly4d_eval for each drone: pieces [d, 4, 8] at times [d], with the body rates the
    firmware derives from differential flatness (thrust along the acceleration plus gravity)."""
    values = values_and_derivatives(coefficients, t)      # [d, 4 axes, 4 derivatives]
    pos, vel, acc, jerk = (values[:, :3, k].copy() for k in range(4))
    yaw, yaw_rate = values[:, 3, 0].copy(), values[:, 3, 1]
    return Evaluation(pos, vel, acc, jerk, yaw, body_rates(acc, jerk, yaw, yaw_rate))


def _normalized(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(np.einsum("ij,ij->i", v, v))[:, None]


def body_rates(acc, jerk, yaw, yaw_rate) -> np.ndarray:
    """The firmware's angular velocity from acceleration, jerk [d, 3], yaw and yaw rate [d]."""
    thrust = acc + np.array([0.0, 0.0, GRAVITY_MPS2])
    z_body = _normalized(thrust)
    x_world = np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros(len(yaw))])
    y_body = _normalized(np.cross(z_body, x_world))
    x_body = np.cross(y_body, z_body)
    along = np.einsum("ij,ij->i", jerk, z_body)
    h_w = (jerk - along[:, None] * z_body) * (1.0 / np.sqrt(np.einsum("ij,ij->i", thrust, thrust)))[:, None]
    return np.column_stack([-np.einsum("ij,ij->i", h_w, y_body), np.einsum("ij,ij->i", h_w, x_body),
                            z_body[:, 2] * yaw_rate])


def rotate_and_shift(ev: Evaluation, rows: np.ndarray, shift: np.ndarray, rotation: np.ndarray) -> None:
    """traj_eval_transform on the drones ``rows`` of ``ev``: position, velocity and acceleration
    turned about z by the wrapped ``rotation`` [r], yaw turned with them, then the position shifted
    by ``shift`` [r, 3] (the jerk and the body rates stay as evaluated, as in the firmware)."""
    angle = normalize_radians(rotation)
    c, s = np.cos(angle), np.sin(angle)
    for field in ("pos", "vel", "acc"):
        v = getattr(ev, field)
        x, y = v[rows, 0].copy(), v[rows, 1].copy()
        v[rows, 0], v[rows, 1] = c * x - s * y, s * x + c * y
    ev.yaw[rows] += angle
    ev.pos[rows] += shift
