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
from typing import Optional

import numpy as np

from composed_sim.core import world_edits
from composed_sim.core.flight import Drones
from composed_sim.core.odometry import Odometry, WheelActuator, WheelNoise, WheelReadings, differential_steering
from composed_sim.core.frames import SensorFrame
from composed_sim.core.engine import physics_engine
from composed_sim.core.placement import place_robots
from composed_sim.core.scene import static_scene
from composed_sim.devices.common.floor import Floor
from composed_sim.devices.common.geometry import StaticScene, box_corners
from composed_sim.devices.common.noise import NoiseStream
from composed_sim.devices.common.sensing import SensedGroup
from composed_sim.world.robot_models import DIFFERENTIAL_STEERING, GROUND, RobotModel, get_model
from composed_sim.core.seeding import STREAM_PLACEMENT, stream
from composed_sim.core.senses import RobotRows, Senses, SensingInputs
from composed_sim.world.schema import Box, World


class PhaseTimes:
    """Wall seconds spent per phase, summed over the run."""

    def __init__(self, senses: Senses):
        self.physics_s = 0.0
        self._senses = senses

    @property
    def sensing_s(self) -> float:
        return self._senses.seconds     # readings are read on first use, by whoever uses them


class Simulation:
    def __init__(self, world: World, *, base_dir: str = "."):
        self.world = world
        self.names: list[str] = world.robot_names()
        self.n = len(self.names)
        self.models: list[RobotModel] = [get_model(world.robots[g].model) for g in world.group_of_robot()]
        self.senses = Senses(world)       # the sensors: their static facts and noise streams
        self.groups: list[SensedGroup] = self.senses.groups
        self.tick = 0
        self.times = PhaseTimes(self.senses)

        positions, headings = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
        self.initial_positions, self.initial_headings = positions, headings
        # Drones fly (core/flight.py): their firmware moves them, the 2D physics holds the others.
        flying = np.array([m.flies for m in self.models], dtype=bool).reshape(self.n)
        self.drones: Optional[Drones] = Drones(world, self.models, positions, headings) if flying.any() else None
        self.wheeled = np.flatnonzero(~flying)             # [w] the robots of the physics, in its order
        self.altitudes = np.zeros(self.n)                  # [n] m above the floor (0 on wheels)
        # One space, cells, or regions in worker processes (core/engine.py): close() ends the workers.
        self.physics = physics_engine(world, [self.models[i] for i in self.wheeled], positions[self.wheeled],
                                      headings[self.wheeled])
        self.scene = static_scene(world)
        self.floor = (Floor.from_world(world.floor, arena_size=world.arena.size, base_dir=base_dir)
                      if any(GROUND in g.running for g in self.groups) else None)

        # Per-robot facts, [n] each, from the models (one place: robot_models.py).
        self.radii, self.heights = self.senses.radii, self.senses.heights
        self.wheel_separation_m = np.array([m.wheel_separation_m for m in self.models], dtype=np.float64)
        # [n, L, 3]; a model with fewer LEDs has black (never seen) padding at the end.
        self.led_colors = np.zeros((self.n, self.senses.n_leds, 3), dtype=np.uint8)   # all LEDs start off

        # The wheels' noise (actuator and sensor), per robot and tick like every device's.
        wheels = [world.robots[g].devices.wheels for g in world.group_of_robot()]
        noise = WheelNoise(*(np.array([getattr(w, f) for w in wheels], dtype=np.float64).reshape(self.n)
                             for f in ("bias_mean_mps", "bias_std_mps", "factor_mean", "factor_std")))
        self.wheel_actuator = WheelActuator(noise, NoiseStream(world.seed, "wheels"))
        self._wheel_sensor_stream = NoiseStream(world.seed, DIFFERENTIAL_STEERING)
        self._wheel_sensor_noise = tuple(np.array([getattr(w, f) for w in wheels], dtype=np.float64).reshape(self.n)
                                         for f in ("velocity_noise_mps", "distance_noise_m"))
        self._applied = (np.zeros(self.n), np.zeros(self.n))   # wheel speeds acting now (after noise)
        self.odometry = Odometry(self.n)
        self._wheels = differential_steering(*self._applied, world.tick_s, self.wheel_separation_m)

        # Range and bearing: what each robot broadcasts (set before a step, heard after it).
        self.rab_payloads = np.zeros((self.n, world.range_and_bearing.payload_bytes), dtype=np.uint8)   # [n, B]

        self.positions, self.headings = self._poses()
        self._inputs = self._snapshot(route_messages=False)
        self._frame: Optional[SensorFrame] = None

    @property
    def physics_processes(self) -> int:
        """Processes stepping the physics: 1 (this one), or the regions' or cells' workers (core/engine.py)."""
        return len(getattr(self.physics, "pids", ())) or 1

    def close(self) -> None:
        """End the physics regions' worker processes, if any (idempotent; they also end with this process)."""
        close = getattr(self.physics, "close", None)
        if close is not None:
            close()

    def __enter__(self) -> "Simulation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

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
                                                np.asarray(right_mps, dtype=np.float64), self.tick)
        if self.drones is None:
            self.physics.set_wheel_speeds(left, right)
            self._applied = self.physics.wheel_speeds()
            return
        self.physics.set_wheel_speeds(left[self.wheeled], right[self.wheeled])     # a drone's wheels: none
        self._applied = (np.zeros(self.n), np.zeros(self.n))
        self._applied[0][self.wheeled], self._applied[1][self.wheeled] = self.physics.wheel_speeds()

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
        """One tick: the commands given since the last step act, physics runs, sensors read."""
        self.advance()
        return self.frame

    def advance(self) -> None:
        """``step`` without reading the sensors: the wheels and odometry integrate, and what the
        sensors will read is kept (``sensing_inputs``; the readings, on first use: ``frame``)."""
        t0 = time.perf_counter()
        self.physics.step()
        self.tick += 1
        if self.drones is not None:
            self.drones.advance(self.tick)
        self.positions, self.headings = self._poses()
        self._wheels = differential_steering(*self._applied, self.world.tick_s, self.wheel_separation_m,
                                             velocity_noise_mps=self._wheel_sensor_noise[0],
                                             distance_noise_m=self._wheel_sensor_noise[1],
                                             rng=self._wheel_sensor_stream.at(self.tick, np.arange(self.n)))
        self.odometry.update(self._wheels)
        self._inputs = self._snapshot(route_messages=True)
        self._frame = None
        self.times.physics_s += time.perf_counter() - t0

    def _poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Every robot's position [n, 2] and heading [n]: the physics' and the drones' (whose
        altitudes are written too)."""
        if self.drones is None:
            return self.physics.poses()
        positions, headings = np.zeros((self.n, 2)), np.zeros(self.n)
        positions[self.wheeled], headings[self.wheeled] = self.physics.poses()
        self.drones.place(positions, headings, self.altitudes)
        return positions, headings

    def _snapshot(self, *, route_messages: bool) -> SensingInputs:
        info = None
        if self.drones is not None:
            info = np.zeros(self.n, dtype=np.uint16)
            info[self.drones.robots] = self.drones.supervisor_info()
        return SensingInputs(self.tick, self.positions, self.headings, self.led_colors.copy(),
                             self.rab_payloads.copy(), self.current_scene(), self.floor, tuple(self.world.lights),
                             route_messages, None if self.drones is None else self.altitudes.copy(), info)

    def sensing_inputs(self) -> SensingInputs:
        """What the sensors read after the last step (the world edits made since are not in it)."""
        return self._inputs

    def robot_rows(self, start: int = 0, stop: Optional[int] = None) -> RobotRows:
        """The wheels' and the odometry's readings of robots ``start … stop-1``."""
        block = slice(start, self.n if stop is None else stop)
        w = self._wheels
        return RobotRows(WheelReadings(w.velocities_mps[block], w.distances_m[block], w.axis_length_m[block]),
                         self.odometry.pose[block].copy(), self.odometry.twist(w)[block])

    @property
    def frame(self) -> SensorFrame:
        """Every robot's readings after the last step, read on first use (the worker host's
        processes read their own; a loop function may read them here)."""
        if self._frame is None:
            self._frame = self.senses.frame(self._inputs, self.robot_rows())
        return self._frame

    def sense(self) -> SensorFrame:
        """The readings of the world as it is now (edits since the last step included), which
        ``frame`` and ``sensing_inputs`` then give too: the tick loop reads tick 0 so."""
        self._inputs = self._snapshot(route_messages=self.tick > 0)
        self._frame = None
        return self.frame

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
