"""One simulated world stepped in the ARGoS order: act, physics, sense.

ROS-free. State lives in arrays over all robots (the batch axis is the robots); the hosts feed
commands in as arrays and read sensor frames out as arrays.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.core.geometry import StaticScene
from composed_sim.core.physics import PhysicsWorld
from composed_sim.core.placement import place_robots
from composed_sim.core.robot_models import RobotModel, get_model
from composed_sim.core.seeding import STREAM_NOISE, STREAM_PLACEMENT, stream
from composed_sim.core.sensors import (BlobReadings, blob_camera, led_world_positions, light_ring,
                                       proximity_ring)
from composed_sim.world.schema import World

@dataclass
class SensorFrame:
    """Every robot's sensor readings at the end of one tick."""
    tick: int
    proximity_distances: np.ndarray   # [n, k] m from the rim, inf = no hit
    proximity: np.ndarray             # [n, k] readings in [0, 1]
    light: np.ndarray                 # [n, k] readings in [0, 1]
    blobs: BlobReadings               # CSR over robots


@dataclass
class PhaseTimes:
    """Wall seconds spent per phase, summed over the run."""
    physics_s: float = 0.0
    sensing_s: float = 0.0


class Simulation:
    def __init__(self, world: World):
        self.world = world
        self.names: list[str] = world.robot_names()
        self.n = len(self.names)
        self.models: list[RobotModel] = [get_model(world.robots[g].model) for g in world.group_of_robot()]
        kinds = {m.name for m in self.models}
        if len(kinds) > 1:
            raise ValueError(f"this build simulates one robot model per world, got {sorted(kinds)}")
        self.model = self.models[0] if self.models else get_model("foot-bot")
        self.tick = 0
        self.times = PhaseTimes()

        positions, headings = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
        self.initial_positions, self.initial_headings = positions, headings
        self.physics = PhysicsWorld(world, self.models, positions, headings)
        self.scene = StaticScene.from_world(world)
        self.noise_rng = stream(world.seed, STREAM_NOISE)

        m = self.model
        self.radii = np.full(self.n, m.body_radius_m)          # [n]
        self.heights = np.full(self.n, m.body_height_m)        # [n]
        self.camera_heights = np.full(self.n, m.camera.height_m)
        apertures = np.radians([world.robots[g].camera.aperture_deg for g in world.group_of_robot()])
        self.half_windows = self.camera_heights * np.tan(apertures)   # [n] square window half-side
        self.led_body = m.led_positions_array()                # [L, 3]
        self.led_colors = np.zeros((self.n, m.n_leds, 3), dtype=np.uint8)   # all LEDs start off
        self.positions, self.headings = self.physics.poses()

    def set_velocity_commands(self, linear: np.ndarray, angular: np.ndarray) -> None:
        """ROS-style (v [n] m/s, ω [n] rad/s) → wheel speeds, acted on at the next step."""
        half = angular * self.model.wheel_separation_m / 2.0
        self.physics.set_wheel_speeds(linear - half, linear + half)

    def set_led_colors(self, robot: int, colors: np.ndarray) -> None:
        """colors: [L, 3] uint8 for one robot."""
        self.led_colors[robot] = colors

    def step(self) -> SensorFrame:
        """One tick: the commands given since the last step act, physics runs, sensors read."""
        t0 = time.perf_counter()
        self.physics.step()
        self.tick += 1
        self.positions, self.headings = self.physics.poses()
        self.times.physics_s += time.perf_counter() - t0
        return self.sense()

    def sense(self) -> SensorFrame:
        t0 = time.perf_counter()
        m, p, h = self.model, self.positions, self.headings
        tree = cKDTree(p)       # one neighbour index per tick, shared by every sensor
        prox_d, prox = proximity_ring(p, h, self.radii, self.heights, m.proximity, self.scene, tree=tree)
        light = light_ring(p, h, self.radii, self.heights, m.light, self.world.lights, self.scene, tree=tree)
        blobs = blob_camera(p, h, self.radii, self.heights, self.camera_heights, self.half_windows,
                            led_world_positions(p, h, self.led_body), self.led_colors, self.scene, tree=tree)
        self.times.sensing_s += time.perf_counter() - t0
        return SensorFrame(self.tick, prox_d, prox, light, blobs)
