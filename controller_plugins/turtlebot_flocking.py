"""The paper's TurtleBot 3 flocking variant: neighbours sensed by LiDAR rays, steering to a goal.

Each LiDAR ray that hits something within the interaction range (1.8 · target distance, as the
foot-bot controller's blob range) is one Lennard-Jones sample (docs/architecture.md, "The flocking
controller"): its hit point, moved from the scanner's mount into base_link, gives a distance and
a bearing. The average of the samples' polar vectors is the flocking vector; the goal vector
points at the goal (from the positioning sensor's pose) with a fixed length. Their sum goes
through the foot-bot controller's turning machine.
"""
from __future__ import annotations

import math

import numpy as np

from composed_sim.ros.contract import twist_of_wheels
from composed_sim.ros.controller import SwarmController, Tick
from controller_plugins.flocking import INTERACTION_RANGE, TurningMachine, flocking_vector


def scan_samples(ranges: np.ndarray, angles: np.ndarray, mount_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finite LiDAR hits [r] (m, rad in the scanner frame) → (bearings, distances) in base_link."""
    hit = np.isfinite(ranges)
    r, a = ranges[hit], angles[hit]
    x = mount_xy[0] + r * np.cos(a)
    y = mount_xy[1] + r * np.sin(a)
    return np.arctan2(y, x), np.hypot(x, y)


def goal_vector(pose: np.ndarray, goal: np.ndarray, length: float) -> np.ndarray:
    """[2] the goal's direction in the robot frame, scaled to ``length`` (zero at the goal)."""
    dx, dy = goal[0] - pose[0], goal[1] - pose[1]
    d = math.hypot(dx, dy)
    if d < 1e-9:
        return np.zeros(2)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([c * dx + s * dy, -s * dx + c * dy]) * (length / d)


class TurtlebotFlockingController(SwarmController):
    """Flock to a goal point with LiDAR-sensed Lennard-Jones spacing (TurtleBot 3 burger)."""

    sensors = ("scan", "pose")

    def __init__(self, **node_kwargs):
        super().__init__("turtlebot_flocking", **node_kwargs)
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("target_distance_m", 0.75), ("gain", 1000.0), ("exponent", 2.0), ("max_speed_mps", 0.15),
            ("goal", [0.0, 0.0]), ("goal_weight", 0.5),
            ("hard_turn_deg", 90.0), ("soft_turn_deg", 70.0), ("no_turn_deg", 10.0))}
        if len(p["goal"]) != 2:
            raise ValueError(f"parameter goal must be [x, y] in m, got {p['goal']}")
        self.goal = np.asarray(p["goal"], dtype=float)
        self.target_cm = 100.0 * p["target_distance_m"]
        self.gain, self.exponent = float(p["gain"]), float(p["exponent"])
        self.max_speed_cm = 100.0 * min(p["max_speed_mps"], self.model.max_wheel_speed_mps)
        self.goal_cm = float(p["goal_weight"]) * self.max_speed_cm
        self.mount_xy = np.asarray(self.model.lidar.mount_m[:2])
        self.turning = TurningMachine(self.max_speed_cm, math.radians(p["hard_turn_deg"]),
                                      math.radians(p["soft_turn_deg"]), math.radians(p["no_turn_deg"]))

    def on_tick(self, tick: Tick) -> tuple[float, float]:
        bearings, distances = scan_samples(tick.scan, self.scan_angles, self.mount_xy)
        near = distances < INTERACTION_RANGE * self.target_cm / 100.0
        heading = (goal_vector(tick.pose, self.goal, self.goal_cm)
                   + flocking_vector(bearings[near], 100.0 * distances[near], self.target_cm, self.gain,
                                     self.exponent, self.max_speed_cm))
        left_cm, right_cm = self.turning.wheel_speeds(heading)
        return twist_of_wheels(left_cm / 100.0, right_cm / 100.0, self.model)
