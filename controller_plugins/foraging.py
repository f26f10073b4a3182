"""Foraging (ARGoS's foraging example): find food on the floor, carry it to the nest under the light.

The ground sensors tell where the robot stands (composed_sim.devices.common.floor.ground_zone): on a black
food spot a robot that carries nothing picks the item up; in the grey nest a carrying robot drops
it. The robot never hears of the loop functions that keep the score and put the food back
elsewhere: it infers what it carries from its own ground readings, as they do. Without food it
random-walks (leaving the nest away from the light); with food it steers to the light. Proximity
avoids walls and robots throughout. LEDs: green while carrying.
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.devices.common.floor import FOOD, NEST, ground_zone
from composed_sim.plugins import ArgosPort
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick
from controller_plugins.diffusion import diffusion_wheels, obstacle_vector

CARRYING = (0, 255, 0)
OFF = (0, 0, 0)


class ForagingController(SwarmController):
    sensors = ("proximity", "light", "ground")
    # ARGoS footbot_foraging: its wheel speed (cm/s). Its rest/explore state machine's
    # probabilities and times have no counterpart here and are listed as not translated.
    argos = ArgosPort("footbot_foraging_controller", {"wheel_turning.max_speed": ("speed_mps", 0.01)})

    def __init__(self, **node_kwargs):
        super().__init__("foraging", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("speed_mps", 0.1), ("food_below", 0.25), ("nest_below", 0.75), ("mean_run_ticks", 40),
            ("alpha_deg", 7.5), ("delta", 0.02), ("heading_tolerance_deg", 20.0))}
        self.speed = min(float(p["speed_mps"]), self.model.max_wheel_speed_mps)
        self.food_below, self.nest_below = float(p["food_below"]), float(p["nest_below"])
        self.mean_run = float(p["mean_run_ticks"])
        self.alpha_rad, self.delta = math.radians(p["alpha_deg"]), float(p["delta"])
        self.tolerance = math.radians(p["heading_tolerance_deg"])
        self.carrying = False
        self.run_left = int(self.rng.geometric(1.0 / self.mean_run))
        self.turn_left, self.turn_sign = 0, 1.0

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        zone = int(ground_zone(tick.ground, self.food_below, self.nest_below))
        if not self.carrying and zone == FOOD:
            self.carrying = True
            self.set_leds(CARRYING)
        elif self.carrying and zone == NEST:
            self.carrying = False
            self.set_leds(OFF)
        obstacle_angle, obstacle = obstacle_vector(tick.proximity, self.proximity_angles)
        if obstacle > self.delta and abs(obstacle_angle) < math.pi / 2:   # something ahead: avoid first
            return self._wheels(diffusion_wheels(tick.proximity, self.proximity_angles, self.alpha_rad,
                                                 self.delta, self.speed, on_the_spot=True))
        light = np.array([np.sum(tick.light * np.cos(self.light_angles)), np.sum(tick.light * np.sin(self.light_angles))])
        if self.carrying and light.any():
            return self._steer(math.atan2(light[1], light[0]))               # home, to the light
        if zone == NEST and light.any():
            return self._steer(math.atan2(-light[1], -light[0]))             # out of the nest
        return self._random_walk()

    def _steer(self, angle: float) -> tuple[float, float]:
        if abs(angle) <= self.tolerance:
            return self._wheels((self.speed, self.speed))
        s = self.speed if angle > 0 else -self.speed
        return self._wheels((-s, s))

    def _random_walk(self) -> tuple[float, float]:
        if self.turn_left > 0:
            self.turn_left -= 1
            s = self.turn_sign * self.speed
            return self._wheels((-s, s))
        self.run_left -= 1
        if self.run_left <= 0:
            self.run_left = int(self.rng.geometric(1.0 / self.mean_run))
            self.turn_left = int(self.rng.integers(1, 10))
            self.turn_sign = 1.0 if self.rng.random() < 0.5 else -1.0
        return self._wheels((self.speed, self.speed))

    def _wheels(self, wheels: tuple[float, float]) -> tuple[float, float]:
        return twist_of_wheels(*wheels, self.model)
