"""One simulated world stepped in the ARGoS order: act, physics, media, sense.

ROS-free. State lives in arrays over all robots (the batch axis is the robots); the hosts feed
commands in as arrays and read sensor frames out as arrays.

A world may mix robot models (a heterogeneous swarm): robots are numbered group by group, in
the world file's order, so each group of the world file is a contiguous block of robots with
one model and one set of device settings. Devices with a layout (proximity, light, camera,
ground, LiDAR) are evaluated per group, vectorised over the group's robots, with every robot
of the world as a body they can see or be blocked by. The wheels, positioning, odometry and
range-and-bearing work on all robots at once.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from typing import Optional

import numpy as np
from scipy.spatial import cKDTree

from composed_sim.core import world_edits
from composed_sim.core.odometry import (Odometry, PoseReadings, WheelActuator, WheelNoise, WheelReadings,
                                        differential_steering, positioning)
from composed_sim.core.physics import PhysicsWorld
from composed_sim.core.placement import place_robots
from composed_sim.core.scene import static_scene
from composed_sim.devices import DEVICES, GROUP_READERS, WITH_LAYOUT
from composed_sim.devices.camera import BlobReadings, led_world_positions
from composed_sim.devices.common.floor import Floor
from composed_sim.devices.common.geometry import StaticScene, box_corners
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.range_and_bearing import RangeAndBearingReadings, range_and_bearing
from composed_sim.world.robot_models import (DIFFERENTIAL_STEERING, GROUND, POSITIONING, RANGE_AND_BEARING,
                                            RobotModel, get_model)
from composed_sim.core.seeding import STREAM_PLACEMENT, device_rng, stream
from composed_sim.world.schema import Box, World


class GroupReadings:
    """The readings of one robot group of the world file (one model); rows follow ``robots``.

    One attribute per reading of each device with a per-group ``read`` (its ``readings`` and
    ``csr_readings``, in its module of ``devices/``, which says their shapes): the foot-bot's
    ``proximity_distances`` and ``proximity`` [g, k], ``light`` [g, k], ``blobs`` (CSR over the
    group's robots), ``ground`` [g, s], ``lidar`` [g, r]. A device the group does not run: None.
    """

    def __init__(self, model: str, robots: slice):
        self.model = model
        self.robots = robots                        # the group's robots: a contiguous index range
        for name in _ROW_ARRAYS + _CSR:
            setattr(self, name, None)


# GroupReadings' arrays with one row per robot, and its CSR readings (cut by csr_rows).
_ROW_ARRAYS = tuple(name for d in DEVICES for name in d.readings)
_CSR = tuple(name for d in DEVICES for name in d.csr_readings)


@dataclass
class SensorFrame:
    """Every robot's sensor readings at the end of one tick."""
    tick: int
    groups: list[GroupReadings]        # one per robot group of the world file, in its order
    pose: PoseReadings                 # positioning sensor, all robots
    wheels: WheelReadings              # differential steering sensor, all robots
    odometry: np.ndarray               # [n, 3] x, y, yaw in each robot's odom frame
    odometry_twist: np.ndarray         # [n, 2] linear (m/s), angular (rad/s) from the wheels
    # CSR over all robots; None when no robot runs the device.
    range_and_bearing: Optional[RangeAndBearingReadings] = None

    # The device arrays over all robots, for worlds whose robots all share one group layout
    # (the hosts written for the foot-bot flocking experiments read these).
    @property
    def proximity_distances(self) -> np.ndarray:
        return self._only("proximity_distances")

    @property
    def proximity(self) -> np.ndarray:
        return self._only("proximity")

    @property
    def light(self) -> np.ndarray:
        return self._only("light")

    @property
    def blobs(self) -> BlobReadings:
        return self._only("blobs")

    def rows(self, start: int, stop: int) -> "SensorFrame":
        """The readings of robots ``start … stop-1`` only, renumbered from 0: what a worker process
        serving that block of robots needs (hosts/workers.py), and nothing of the others'."""
        groups = []
        for g in self.groups:
            # The group's robots inside the block; a group outside it keeps an empty slice.
            lo = min(max(g.robots.start, start), g.robots.stop)
            hi = max(lo, min(g.robots.stop, stop))
            within = slice(lo - g.robots.start, hi - g.robots.start)
            cut = GroupReadings(g.model, slice(max(lo - start, 0), max(hi - start, 0)))
            for f in _ROW_ARRAYS:
                value = getattr(g, f)
                setattr(cut, f, None if value is None else value[within])
            for f in _CSR:
                value = getattr(g, f)
                setattr(cut, f, None if value is None else csr_rows(value, within.start, within.stop))
            groups.append(cut)
        block = slice(start, stop)
        return SensorFrame(self.tick, groups,
                           PoseReadings(self.pose.positions[block], self.pose.yaws[block],
                                        self.pose.quaternions[block]),
                           WheelReadings(self.wheels.velocities_mps[block], self.wheels.distances_m[block],
                                         self.wheels.axis_length_m[block]),
                           self.odometry[block], self.odometry_twist[block],
                           None if self.range_and_bearing is None
                           else csr_rows(self.range_and_bearing, start, stop))

    def _only(self, device: str):
        if len(self.groups) != 1:
            raise ValueError(f"frame.{device} is for one-group worlds; this world has {len(self.groups)} "
                             f"groups: read frame.groups[i].{device}")
        value = getattr(self.groups[0], device)
        if value is None:
            raise ValueError(f"the {self.groups[0].model} robots do not run the {device.split('_')[0]} device")
        return value


def csr_rows(readings, start: int, stop: int):
    """A CSR readings dataclass (``offsets`` [n+1] and entry arrays [m, …]) cut to rows
    ``start … stop-1``, renumbered from 0."""
    first, last = int(readings.offsets[start]), int(readings.offsets[stop])
    entries = {f.name: getattr(readings, f.name)[first:last] for f in fields(readings) if f.name != "offsets"}
    return replace(readings, offsets=readings.offsets[start:stop + 1] - first, **entries)


@dataclass
class PhaseTimes:
    """Wall seconds spent per phase, summed over the run."""
    physics_s: float = 0.0
    sensing_s: float = 0.0


class Simulation:
    def __init__(self, world: World, *, base_dir: str = "."):
        self.world = world
        self.names: list[str] = world.robot_names()
        self.n = len(self.names)
        self.models: list[RobotModel] = [get_model(world.robots[g].model) for g in world.group_of_robot()]
        self.groups: list[SensedGroup] = []
        start = 0
        for gi, g in enumerate(world.robots):
            model = get_model(g.model)
            self.groups.append(SensedGroup(gi, model, slice(start, start + g.count), g.devices.running(model),
                                           g.devices))
            start += g.count
        self.tick = 0
        self.times = PhaseTimes()

        positions, headings = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
        self.initial_positions, self.initial_headings = positions, headings
        self.physics = PhysicsWorld(world, self.models, positions, headings)
        self.scene = static_scene(world)
        self.floor = (Floor.from_world(world.floor, arena_size=world.arena.size, base_dir=base_dir)
                      if any(GROUND in g.running for g in self.groups) else None)

        # Per-robot facts, [n] each, from the models (one place: robot_models.py).
        def per_robot(fn, dtype=np.float64):
            return np.array([fn(m) for m in self.models], dtype=dtype).reshape(self.n)
        self.radii = per_robot(lambda m: m.body_radius_m)
        self.heights = per_robot(lambda m: m.body_height_m)
        self.wheel_separation_m = per_robot(lambda m: m.wheel_separation_m)
        self.camera_heights = per_robot(lambda m: m.camera.height_m if m.camera else 0.0)
        apertures = np.radians([world.robots[g].camera.aperture_deg for g in world.group_of_robot()])
        self.half_windows = self.camera_heights * np.tan(apertures)   # [n] square window half-side
        kinds = {m.name for m in self.models}
        self._one_model = len(kinds) <= 1
        self.led_counts = per_robot(lambda m: m.n_leds, np.intp)         # [n]
        first = self.models[0] if self.models else get_model("foot-bot")
        self.led_body = first.led_positions_array()     # [L, 3], every robot's in a one-model world
        n_leds = int(self.led_counts.max()) if self.n else first.n_leds
        # [n, L, 3]; a model with fewer LEDs has black (never seen) padding at the end.
        self.led_colors = np.zeros((self.n, n_leds, 3), dtype=np.uint8)   # all LEDs start off

        # One noise generator per device (and the wheels' actuator), seeded by its name.
        self._rngs = {name: device_rng(world.seed, name) for name in
                      (*WITH_LAYOUT, "wheels", DIFFERENTIAL_STEERING, POSITIONING)}
        wheels = [world.robots[g].devices.wheels for g in world.group_of_robot()]
        noise = WheelNoise(*(np.array([getattr(w, f) for w in wheels], dtype=np.float64).reshape(self.n)
                             for f in ("bias_mean_mps", "bias_std_mps", "factor_mean", "factor_std")))
        self.wheel_actuator = WheelActuator(noise, self._rngs["wheels"])
        self._wheel_sensor_noise = tuple(np.array([getattr(w, f) for w in wheels], dtype=np.float64).reshape(self.n)
                                         for f in ("velocity_noise_mps", "distance_noise_m"))
        pos_cfg = [world.robots[g].devices.config("positioning") for g in world.group_of_robot()]
        self._pose_noise = tuple(np.array([getattr(c, f) for c in pos_cfg], dtype=np.float64).reshape(self.n)
                                 for f in ("position_noise_m", "yaw_noise_rad"))
        self._applied = (np.zeros(self.n), np.zeros(self.n))   # wheel speeds acting now (after noise)
        self.odometry = Odometry(self.n)
        self._wheels = differential_steering(*self._applied, world.tick_s, self.wheel_separation_m)

        # Range and bearing: what each robot broadcasts (set before a step, heard after it).
        medium = world.range_and_bearing
        self.rab_equipped = np.zeros(self.n, dtype=bool)
        self.rab_elevations = np.zeros(self.n)
        self.rab_ranges = np.zeros(self.n)
        self._rab_drop = np.zeros(self.n)
        self._rab_noise = np.zeros(self.n)
        for g in self.groups:
            if RANGE_AND_BEARING in g.running:
                cfg = g.settings.config(RANGE_AND_BEARING)
                self.rab_equipped[g.robots] = True
                self.rab_elevations[g.robots] = g.model.range_and_bearing.elevation_m
                self.rab_ranges[g.robots] = cfg.range_m or g.model.range_and_bearing.range_m
                self._rab_drop[g.robots] = cfg.packet_drop_probability
                self._rab_noise[g.robots] = cfg.noise_std_m
        self.rab_payloads = np.zeros((self.n, medium.payload_bytes), dtype=np.uint8)   # [n, B]
        self._rab: Optional[RangeAndBearingReadings] = (
            RangeAndBearingReadings.empty(self.n, medium.payload_bytes) if self.rab_equipped.any() else None)

        self.positions, self.headings = self.physics.poses()
        self.frame: Optional[SensorFrame] = None

    # --- world edits between ticks (loop functions): core/world_edits.py ---------------

    def move_object(self, index: int, position, yaw_rad: Optional[float] = None) -> None:
        world_edits.move_object(self, index, position, yaw_rad)

    def add_object(self, obstacle) -> int:
        return world_edits.add_object(self, obstacle)

    def set_floor_shape(self, index: int, **changes) -> None:
        world_edits.set_floor_shape(self, index, **changes)

    def add_floor_shape(self, shape) -> int:
        return world_edits.add_floor_shape(self, shape)

    def set_light(self, index: int, **changes) -> None:
        world_edits.set_light(self, index, **changes)

    # --- commands (act at the next step) ---------------------------------------------

    def set_velocity_commands(self, linear: np.ndarray, angular: np.ndarray) -> None:
        """ROS-style (v [n] m/s, ω [n] rad/s) → wheel speeds, acted on at the next step."""
        half = angular * self.wheel_separation_m / 2.0
        self.set_wheel_speeds(linear - half, linear + half)

    def set_wheel_speeds(self, left_mps: np.ndarray, right_mps: np.ndarray) -> None:
        """ARGoS-style wheel speeds [n] each (m/s), with the actuator noise, at the next step."""
        left, right = self.wheel_actuator.apply(np.asarray(left_mps, dtype=np.float64),
                                                np.asarray(right_mps, dtype=np.float64))
        self.physics.set_wheel_speeds(left, right)
        self._applied = self.physics.wheel_speeds()

    def set_led_colors(self, robot: int, colors: np.ndarray) -> None:
        """colors: [L, 3] uint8 for one robot (L = its model's LED count)."""
        self.led_colors[robot, :len(colors)] = colors

    def set_rab_payload(self, robot: int, data) -> None:
        """What ``robot`` broadcasts from the next step on: bytes or [B] uint8, B = payload_bytes."""
        payload = np.frombuffer(bytes(data), dtype=np.uint8) if isinstance(data, (bytes, bytearray)) \
            else np.asarray(data, dtype=np.uint8)
        if payload.shape != self.rab_payloads.shape[1:]:
            raise ValueError(f"a payload has {self.rab_payloads.shape[1]} bytes (range_and_bearing."
                             f"payload_bytes), got {payload.shape[0] if payload.ndim == 1 else payload.shape}")
        self.rab_payloads[robot] = payload

    # --- the tick ------------------------------------------------------------------------

    def step(self) -> SensorFrame:
        """One tick: the commands given since the last step act, physics runs, messages are
        routed, sensors read."""
        t0 = time.perf_counter()
        self.physics.step()
        self.tick += 1
        self.positions, self.headings = self.physics.poses()
        self._wheels = differential_steering(*self._applied, self.world.tick_s, self.wheel_separation_m,
                                             velocity_noise_mps=self._wheel_sensor_noise[0],
                                             distance_noise_m=self._wheel_sensor_noise[1],
                                             rng=self._rngs[DIFFERENTIAL_STEERING])
        self.odometry.update(self._wheels)
        self.times.physics_s += time.perf_counter() - t0
        return self.sense(media=True)

    def current_scene(self) -> StaticScene:
        """Static bodies plus the movable objects where they are now."""
        if not self.physics.movable:
            return self.scene
        pos, yaw = self.physics.movable_poses()
        boxes = [i for i, ob in enumerate(self.physics.movable) if isinstance(ob, Box)]
        cyls = [i for i, ob in enumerate(self.physics.movable) if not isinstance(ob, Box)]
        mov = self.physics.movable
        return self.scene.with_bodies(
            pos[cyls], np.array([mov[i].radius_m for i in cyls]), np.array([mov[i].height_m for i in cyls]),
            np.array([box_corners(pos[i], mov[i].size, yaw[i]) for i in boxes]).reshape(-1, 4, 2),
            np.array([mov[i].height_m for i in boxes]))

    def sense(self, *, media: bool = False) -> SensorFrame:
        """The readings of the current state; ``media``: route this tick's messages first (a step does)."""
        t0 = time.perf_counter()
        p, h = self.positions, self.headings
        tree = cKDTree(p)       # one neighbour index per tick, shared by every sensor
        scene = self.current_scene()
        if media and self._rab is not None:
            self._rab = range_and_bearing(
                p, h, self.radii, self.heights, self.rab_equipped, self.rab_elevations, self.rab_ranges,
                self.rab_payloads, scene, mode=self.world.range_and_bearing.mode,
                check_occlusions=self.world.range_and_bearing.check_occlusions,
                drop_probability=self._rab_drop, noise_std_m=self._rab_noise,
                rng=self._rngs[RANGE_AND_BEARING], tree=tree)
        sensing = Sensing(p, h, self.radii, self.heights, scene, tree, self._rngs, self.world.lights, self.floor,
                          self.camera_heights, self.half_windows, self.led_colors, self._led_world,
                          one_group=len(self.groups) == 1)
        groups = []
        for g in self.groups:
            out = GroupReadings(g.model.name, g.robots)
            for device in g.running:           # devices/: each reads the group into its fields
                if device in GROUP_READERS:
                    GROUP_READERS[device](sensing, g, out)
            groups.append(out)
        pose = positioning(p, h, position_noise_m=self._pose_noise[0], yaw_noise_rad=self._pose_noise[1],
                           rng=self._rngs[POSITIONING])
        frame = SensorFrame(self.tick, groups, pose, self._wheels, self.odometry.pose.copy(),
                            self.odometry.twist(self._wheels), self._rab)
        self.times.sensing_s += time.perf_counter() - t0
        self.frame = frame      # the latest readings, for loop functions (composed_sim/loop_functions.py)
        return frame

    def _led_world(self) -> np.ndarray:
        """[n, L, 3] world-frame LED positions of every robot (padding LEDs at the robot's centre)."""
        if self._one_model:
            return led_world_positions(self.positions, self.headings, self.led_body)
        out = np.zeros(self.led_colors.shape, dtype=np.float64)
        for g in self.groups:
            body = g.model.led_positions_array()
            if len(body):
                out[g.robots, :len(body)] = led_world_positions(self.positions[g.robots], self.headings[g.robots],
                                                                body)
            out[g.robots, len(body):, :2] = self.positions[g.robots, None, :]
        return out
