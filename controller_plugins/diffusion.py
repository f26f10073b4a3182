"""Diffusion with obstacle avoidance (argos3-examples, footbot_diffusion) as an rclpy Node.

Go straight while the proximity ring sees nothing ahead; otherwise turn on the spot away from
the obstacle. The accumulated proximity vector decides: if its angle is within ±alpha of the
front and its length below delta, nothing is in the way. Any model with a proximity ring works
(foot-bot 24 sensors, e-puck 8, Thymio 7); the ring's angles come from the robot model.
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick


def obstacle_vector(readings: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
    """Mean of the sensors' polar vectors → (angle rad, length) of where the obstacles are."""
    x = float(np.sum(readings * np.cos(angles))) / len(readings)
    y = float(np.sum(readings * np.sin(angles))) / len(readings)
    return math.atan2(y, x), math.hypot(x, y)


def diffusion_wheels(readings: np.ndarray, angles: np.ndarray, alpha_rad: float, delta: float,
                     speed: float) -> tuple[float, float]:
    """(left, right) wheel speeds: straight when the way is free, else turn away on the spot-ish
    (ARGoS: the wheel on the obstacle's side keeps the speed, the other stops)."""
    angle, length = obstacle_vector(readings, angles)
    if -alpha_rad <= angle <= alpha_rad and length < delta:
        return speed, speed
    return (speed, 0.0) if angle > 0.0 else (0.0, speed)


class DiffusionController(SwarmController):
    """Spread out over the arena, avoiding walls and each other with the proximity ring."""

    sensors = ("proximity",)

    def __init__(self, **node_kwargs):
        super().__init__("diffusion", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("alpha_deg", 7.5), ("delta", 0.1), ("speed_mps", 0.1))}
        self.alpha_rad = math.radians(p["alpha_deg"])
        self.delta = float(p["delta"])
        self.speed = min(float(p["speed_mps"]), self.model.max_wheel_speed_mps)

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        left, right = diffusion_wheels(tick.proximity, self.proximity_angles, self.alpha_rad, self.delta,
                                       self.speed)
        return twist_of_wheels(left, right, self.model)
