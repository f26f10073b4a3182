"""Aggregation on a floor patch with the ground sensors (e-puck, Thymio or foot-bot).

Off the patch a robot random-walks: straight runs of random length, random turns, and the
diffusion controller's obstacle avoidance. When its ground sensors read the patch (mean grey
level below ``dark_threshold``) it stops, and lights its LEDs; robots on the patch stay, so the
fraction of the swarm on it grows. Turns and run lengths come from the robot's own generator.
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick
from controller_plugins.diffusion import diffusion_wheels

ON_PATCH = (0, 0, 255)


class AggregationController(SwarmController):
    """Random walk until the ground sensors see the dark patch, then stay."""

    sensors = ("proximity", "ground")

    def __init__(self, **node_kwargs):
        super().__init__("aggregation", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("speed_mps", 0.1), ("dark_threshold", 0.5), ("mean_run_ticks", 30), ("turn_ticks", 8),
            ("alpha_deg", 7.5), ("delta", 0.1))}
        self.speed = min(float(p["speed_mps"]), self.model.max_wheel_speed_mps)
        self.dark = float(p["dark_threshold"])
        self.mean_run = float(p["mean_run_ticks"])
        self.turn_ticks = int(p["turn_ticks"])
        self.alpha_rad, self.delta = math.radians(p["alpha_deg"]), float(p["delta"])
        self.run_left = int(self.rng.geometric(1.0 / self.mean_run))
        self.turn_left, self.turn_sign = 0, 1.0
        self.stopped = False

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        if float(np.mean(tick.ground)) < self.dark:
            if not self.stopped:
                self.set_leds(ON_PATCH)
                self.stopped = True
            return 0.0, 0.0
        if self.stopped:                 # pushed off the patch: walk again
            self.set_leds((0, 0, 0))
            self.stopped = False
        if self.turn_left > 0:           # a random turn on the spot
            self.turn_left -= 1
            s = self.turn_sign * self.speed
            return twist_of_wheels(-s, s, self.model)
        self.run_left -= 1
        if self.run_left <= 0:
            self.run_left = int(self.rng.geometric(1.0 / self.mean_run))
            self.turn_left = int(self.rng.integers(1, self.turn_ticks + 1))
            self.turn_sign = 1.0 if self.rng.random() < 0.5 else -1.0
        left, right = diffusion_wheels(tick.proximity, self.proximity_angles, self.alpha_rad, self.delta,
                                       self.speed)
        return twist_of_wheels(left, right, self.model)
