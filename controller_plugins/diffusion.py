"""Diffusion with obstacle avoidance (argos3-examples, footbot_diffusion) as an rclpy Node.

Go straight while the proximity ring sees nothing ahead; otherwise turn away from the obstacle.
The accumulated proximity vector decides: if its angle is within ±alpha of the front and its
length below delta, nothing is in the way. Any model with a proximity ring works (foot-bot 24
sensors, e-puck 8, Thymio 7); the ring's angles come from the robot model.

``turn_on_the_spot: false`` is ARGoS's rule exactly: it turns about the inner wheel, still moving
forward, and turns away from obstacles behind it too; in a crowd two robots turning away from
each other that way keep closing in and touch. ``true`` turns in place, and ignores what is only
behind (going straight moves away from it): robots then never touch each other.
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.plugins import ArgosPort
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick


def obstacle_vector(readings: np.ndarray, angles: np.ndarray) -> tuple[float, float]:
    """Mean of the sensors' polar vectors → (angle rad, length) of where the obstacles are."""
    x = float(np.sum(readings * np.cos(angles))) / len(readings)
    y = float(np.sum(readings * np.sin(angles))) / len(readings)
    return math.atan2(y, x), math.hypot(x, y)


def diffusion_wheels(readings: np.ndarray, angles: np.ndarray, alpha_rad: float, delta: float,
                     speed: float, on_the_spot: bool = False) -> tuple[float, float]:
    """(left, right) wheel speeds: straight when the way is free, else turn away from the
    obstacle. ARGoS turns about the inner wheel (the wheel on the obstacle's side keeps the
    speed, the other stops), still moving forward at half speed; ``on_the_spot`` turns in place
    (the inner wheel runs backwards), which never closes in on what is beside the robot."""
    angle, length = obstacle_vector(readings, angles)
    if -alpha_rad <= angle <= alpha_rad and length < delta:
        return speed, speed
    if on_the_spot and abs(angle) >= math.pi / 2:
        return speed, speed                      # only behind: going straight moves away from it
    inner = -speed if on_the_spot else 0.0
    return (speed, inner) if angle > 0.0 else (inner, speed)


class DiffusionController(SwarmController):
    """Spread out over the arena, avoiding walls and each other with the proximity ring."""

    sensors = ("proximity",)
    # ARGoS footbot_diffusion: alpha (degrees), delta, velocity (cm/s).
    argos = ArgosPort("footbot_diffusion_controller", {
        "alpha": ("alpha_deg", 1.0), "delta": ("delta", 1.0), "velocity": ("speed_mps", 0.01)})

    def __init__(self, **node_kwargs):
        super().__init__("diffusion", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("alpha_deg", 7.5), ("delta", 0.1), ("speed_mps", 0.1), ("turn_on_the_spot", False))}
        self.alpha_rad = math.radians(p["alpha_deg"])
        self.delta = float(p["delta"])
        self.speed = min(float(p["speed_mps"]), self.model.max_wheel_speed_mps)
        self.on_the_spot = bool(p["turn_on_the_spot"])

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        left, right = diffusion_wheels(tick.proximity, self.proximity_angles, self.alpha_rad, self.delta,
                                       self.speed, self.on_the_spot)
        return twist_of_wheels(left, right, self.model)
