"""The ARGoS foot-bot flocking controller (argos3-examples, footbot_flocking) as an rclpy Node.

Each robot lights its beacon red, steers by the sum of a light vector (towards the light) and a
flocking vector (generalised Lennard-Jones over the red blobs it sees), and turns that heading
into wheel speeds with the ARGoS three-state turning machine. ARGoS works in cm and cm/s; the
pure functions below keep its units so they can be checked against its numbers, and the Node
converts at the boundary.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from composed_sim.plugins import ArgosPort
from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick

RED = (255, 0, 0)
BEACON_LED = 12          # the foot-bot's beacon: LED index 12 (after the 12 ring LEDs)
INTERACTION_RANGE = 1.8  # blobs farther than 1.8 · target distance are ignored (ARGoS)
_sum = np.add.reduce     # np.sum without its wrapper: the same pairwise summation


def lennard_jones(distance_cm, target_cm: float, gain: float, exponent: float):
    """Generalised Lennard-Jones: negative (repulsive) below the target distance, positive above."""
    x = (target_cm / distance_cm) ** exponent
    return -gain / distance_cm * (x * x - x)


def flocking_vector(angles: np.ndarray, distances_cm: np.ndarray, target_cm: float, gain: float,
                    exponent: float, max_speed_cm: float) -> np.ndarray:
    """Average LJ polar vector over the blobs within range, clamped to max speed → [2] (x, y)."""
    near = distances_cm < INTERACTION_RANGE * target_cm
    if not near.any():
        return np.zeros(2)
    f = lennard_jones(distances_cm[near], target_cm, gain, exponent)
    v = np.array([np.sum(f * np.cos(angles[near])), np.sum(f * np.sin(angles[near]))]) / near.sum()
    length = math.hypot(*v)
    return v * (max_speed_cm / length) if length > max_speed_cm else v


def light_vector(readings: np.ndarray, angles: np.ndarray, max_speed_cm: float) -> np.ndarray:
    """Sum of the light ring's polar vectors, scaled to a quarter of max speed → [2]."""
    v = np.array([np.sum(readings * np.cos(angles)), np.sum(readings * np.sin(angles))])
    length = math.hypot(*v)
    return v * (0.25 * max_speed_cm / length) if length > 0 else v


class Turn(Enum):
    NO_TURN = 0
    SOFT_TURN = 1
    HARD_TURN = 2


@dataclass
class TurningMachine:
    """Heading vector → (left, right) wheel speeds, with ARGoS's hysteresis between turn modes."""
    max_speed: float
    hard_turn_rad: float
    soft_turn_rad: float
    no_turn_rad: float
    state: Turn = Turn.NO_TURN

    def wheel_speeds(self, heading) -> tuple[float, float]:
        """heading: (x, y)."""
        angle = math.atan2(heading[1], heading[0])     # already in (-pi, pi]
        length = math.hypot(heading[0], heading[1])
        base = min(length, self.max_speed)
        a = abs(angle)
        # Checked in this order within one call so that transitions cascade, as in ARGoS.
        if self.state is Turn.HARD_TURN and a <= self.soft_turn_rad:
            self.state = Turn.SOFT_TURN
        if self.state is Turn.SOFT_TURN:
            if a > self.hard_turn_rad:
                self.state = Turn.HARD_TURN
            elif a <= self.no_turn_rad:
                self.state = Turn.NO_TURN
        if self.state is Turn.NO_TURN:
            if a > self.hard_turn_rad:
                self.state = Turn.HARD_TURN
            elif a > self.no_turn_rad:
                self.state = Turn.SOFT_TURN
        if self.state is Turn.NO_TURN:
            first = second = base
        elif self.state is Turn.SOFT_TURN:
            factor = (self.hard_turn_rad - a) / self.hard_turn_rad
            first, second = base * factor, base * (2.0 - factor)
        else:
            first, second = -self.max_speed, self.max_speed
        return (first, second) if angle > 0 else (second, first)


class FlockingController(SwarmController):
    """Flock towards the light: ARGoS's footbot_flocking, parameters from the world file."""

    sensors = ("light", "blobs")
    # ARGoS footbot_flocking: <flocking> and <wheel_turning> in cm, cm/s and degrees.
    argos = ArgosPort("footbot_flocking_controller", {
        "flocking.target_distance": ("target_distance_m", 0.01),
        "flocking.gain": ("gain", 1.0),
        "flocking.exponent": ("exponent", 1.0),
        "wheel_turning.max_speed": ("max_speed_mps", 0.01),
        "wheel_turning.hard_turn_angle_threshold": ("hard_turn_deg", 1.0),
        "wheel_turning.soft_turn_angle_threshold": ("soft_turn_deg", 1.0),
        "wheel_turning.no_turn_angle_threshold": ("no_turn_deg", 1.0)})

    def __init__(self, **node_kwargs):
        super().__init__("flocking", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("target_distance_m", 0.75), ("gain", 1000.0), ("exponent", 2.0), ("max_speed_mps", 0.10),
            ("hard_turn_deg", 90.0), ("soft_turn_deg", 70.0), ("no_turn_deg", 10.0))}
        self.target_cm = 100.0 * p["target_distance_m"]
        self.gain = float(p["gain"])
        self.exponent = float(p["exponent"])
        self.max_speed_cm = 100.0 * p["max_speed_mps"]
        self.turning = TurningMachine(self.max_speed_cm, math.radians(p["hard_turn_deg"]),
                                      math.radians(p["soft_turn_deg"]), math.radians(p["no_turn_deg"]))
        self._light_cos, self._light_sin = np.cos(self.light_angles), np.sin(self.light_angles)
        self.set_led(BEACON_LED, RED)

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        # light_vector + flocking_vector, computed on plain floats for speed: the same operations
        # in the same order (numpy's sums included), so the very same numbers.
        lx = float(_sum(tick.light * self._light_cos))
        ly = float(_sum(tick.light * self._light_sin))
        length = math.hypot(lx, ly)
        if length > 0:
            scale = 0.25 * self.max_speed_cm / length
            lx, ly = lx * scale, ly * scale
        red = tick.blobs.of_color(RED)
        distances_cm = 100.0 * red.distances
        near = distances_cm < INTERACTION_RANGE * self.target_cm
        count = int(np.count_nonzero(near))
        if count:
            f = lennard_jones(distances_cm[near], self.target_cm, self.gain, self.exponent)
            angles = red.angles[near]
            fx = float(_sum(f * np.cos(angles))) / count
            fy = float(_sum(f * np.sin(angles))) / count
            length = math.hypot(fx, fy)
            if length > self.max_speed_cm:
                scale = self.max_speed_cm / length
                fx, fy = fx * scale, fy * scale
            lx, ly = lx + fx, ly + fy
        left_cm, right_cm = self.turning.wheel_speeds((lx, ly))
        return twist_of_wheels(left_cm / 100.0, right_cm / 100.0, self.model)
