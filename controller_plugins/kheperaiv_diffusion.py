"""The Khepera IV plugin's own diffusion controller (argos3-kheperaiv, ``kheperaiv_diffusion``).

The foot-bot diffusion's rule (controller_plugins/diffusion.py) on the Khepera IV's 8 IR sensors,
except for how it avoids: where the foot-bot turns forward about its inner wheel, this one backs
away, one wheel in reverse and the other stopped (obstacle on the left, angle > 0: the left wheel
goes backwards; on the right: the right wheel does).
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.plugins import ArgosPort
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick
from controller_plugins.diffusion import obstacle_vector


def kheperaiv_diffusion_wheels(readings: np.ndarray, angles: np.ndarray, alpha_rad: float, delta: float,
                               speed: float) -> tuple[float, float]:
    """(left, right) wheel speeds: straight when the way is free (the mean proximity vector within
    ±alpha of the front and shorter than delta), else back away from the obstacle."""
    angle, length = obstacle_vector(readings, angles)
    if -alpha_rad <= angle <= alpha_rad and length < delta:
        return speed, speed
    return (-speed, 0.0) if angle > 0.0 else (0.0, -speed)


class KheperaIVDiffusionController(SwarmController):
    """Spread out, backing away from walls and other robots seen by the IR ring."""

    sensors = ("proximity",)
    # ARGoS kheperaiv_diffusion: alpha (degrees), delta, velocity (cm/s).
    argos = ArgosPort("kheperaiv_diffusion_controller", {
        "alpha": ("alpha_deg", 1.0), "delta": ("delta", 1.0), "velocity": ("speed_mps", 0.01)})

    def __init__(self, **node_kwargs):
        super().__init__("kheperaiv_diffusion", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("alpha_deg", 10.0), ("delta", 0.5), ("speed_mps", 0.025))}
        self.alpha_rad = math.radians(p["alpha_deg"])
        self.delta = float(p["delta"])
        self.speed = min(float(p["speed_mps"]), self.model.max_wheel_speed_mps)

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        left, right = kheperaiv_diffusion_wheels(tick.proximity, self.proximity_angles, self.alpha_rad,
                                                 self.delta, self.speed)
        return twist_of_wheels(left, right, self.model)
