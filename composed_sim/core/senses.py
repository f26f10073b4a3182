"""Every robot's sensors, read from the world's state after a step, for all robots or a block.

The main process reads them for all robots when it hosts the controllers itself (or a loop
function asks for ``sim.frame``); a worker process of the worker host reads its own block from
the same ``SensingInputs`` (hosts/workers/worker_host.py), so the main process's serial part does not grow
with the sensing. The noise is counter-based per robot (devices/common/noise.py): a robot's
readings are the same whoever reads them, and whenever: a frame reads each device's readings on
their first use (core/frames.py), so what nobody reads is never computed.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from composed_sim.core.frames import GroupReadings, SensorFrame
from composed_sim.core.odometry import WheelReadings, positioning
from composed_sim.devices import GROUP_READERS, READINGS, WITH_LAYOUT
from composed_sim.devices.camera import leds_at
from composed_sim.devices.common.floor import Floor
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.common.noise import NoiseStream
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import kd_tree
from composed_sim.devices.range_and_bearing import RangeAndBearingReadings, range_and_bearing
from composed_sim.world.robot_models import POSITIONING, RANGE_AND_BEARING, get_model
from composed_sim.world.schema import World


@dataclass
class SensingInputs:
    """What the sensors read of the world after a step (a snapshot: later edits do not change it)."""
    tick: int
    positions: np.ndarray            # [n, 2] m
    headings: np.ndarray             # [n] rad
    led_colors: np.ndarray           # [n, L, 3] uint8
    rab_payloads: np.ndarray         # [n, B] uint8: what each robot broadcast during the step
    scene: StaticScene               # static bodies and the movable objects where they are now
    floor: Optional[Floor]
    lights: Sequence
    route_messages: bool             # range and bearing: messages sent (false before the first step)
    altitudes: Optional[np.ndarray] = None   # [n] m above the floor (None: every robot on it)
    # [n] uint16: each drone's Status.supervisor_info bits after the step, 0 for a robot on wheels
    # (None: no robot flies); what a drone's ``status`` topic says (ros/crazyflie/endpoints.py).
    supervisor_info: Optional[np.ndarray] = None
    # The neighbour index of ``positions`` (devices/common/sensors.kd_tree) when its reader got it
    # built (a worker gets the main process's, hosts/workers/shared_state.py); None: built here.
    tree: Optional[object] = None


@dataclass
class RobotRows:
    """The per-robot readings the main process integrates (wheels, odometry), for some rows."""
    wheels: WheelReadings
    odometry: np.ndarray             # [m, 3]
    odometry_twist: np.ndarray       # [m, 2]


class Senses:
    """The sensors of a world's robot groups, with their static facts and noise streams."""

    def __init__(self, world: World):
        self.world = world
        self.n = len(world.robot_names())
        self.groups: list[SensedGroup] = []
        start = 0
        for gi, g in enumerate(world.robots):
            model = get_model(g.model)
            self.groups.append(SensedGroup(gi, model, slice(start, start + g.count), g.devices.running(model),
                                           g.devices))
            start += g.count
        models = [get_model(world.robots[g].model) for g in world.group_of_robot()]

        def per_robot(fn, dtype=np.float64):
            return np.array([fn(m) for m in models], dtype=dtype).reshape(self.n)
        self.radii = per_robot(lambda m: m.body_radius_m)
        self.heights = per_robot(lambda m: m.body_height_m)
        self.camera_heights = per_robot(lambda m: m.camera.height_m if m.camera else 0.0)
        apertures = np.radians([world.robots[g].camera.aperture_deg for g in world.group_of_robot()])
        self.half_windows = self.camera_heights * np.tan(apertures)   # [n] square window half-side
        first = models[0] if models else get_model("foot-bot")
        self.n_leds = max((m.n_leds for m in models), default=first.n_leds)
        # Every robot's LEDs in its body frame, [1, L, 3] when all robots share a model, else
        # [n, L, 3] (a model with fewer LEDs padded at its centre: they are never lit).
        if len({m.name for m in models}) <= 1:
            self.led_bodies = first.led_positions_array()[None]
        else:
            self.led_bodies = np.zeros((self.n, self.n_leds, 3))
            for g in self.groups:
                body = g.model.led_positions_array()
                self.led_bodies[g.robots, :len(body)] = body

        pos_cfg = [world.robots[g].devices.config(POSITIONING) for g in world.group_of_robot()]
        self.pose_noise = tuple(np.array([getattr(c, f) for c in pos_cfg], dtype=np.float64).reshape(self.n)
                                for f in ("position_noise_m", "yaw_noise_rad"))
        # Range and bearing: who has one, its height and range, and each receiver's noise.
        self.rab_equipped = np.zeros(self.n, dtype=bool)
        self.rab_elevations = np.zeros(self.n)
        self.rab_ranges = np.zeros(self.n)
        self.rab_drop = np.zeros(self.n)
        self.rab_noise = np.zeros(self.n)
        for g in self.groups:
            if RANGE_AND_BEARING in g.running:
                cfg = g.settings.config(RANGE_AND_BEARING)
                self.rab_equipped[g.robots] = True
                self.rab_elevations[g.robots] = g.model.range_and_bearing.elevation_m
                self.rab_ranges[g.robots] = cfg.range_m or g.model.range_and_bearing.range_m
                self.rab_drop[g.robots] = cfg.packet_drop_probability
                self.rab_noise[g.robots] = cfg.noise_std_m
        self.seconds = 0.0               # spent reading, summed over the run (read on first use too)
        self.streams = {name: NoiseStream(world.seed, name)
                        for name in (*WITH_LAYOUT, RANGE_AND_BEARING, POSITIONING)}

    def frame(self, inputs: SensingInputs, rows: RobotRows, block: Optional[slice] = None) -> SensorFrame:
        """The readings of the robots in ``block`` (None: all), renumbered from 0; ``rows``: their
        wheels and odometry, as the main process integrated them."""
        t0 = time.perf_counter()
        block = slice(0, self.n) if block is None else block
        p, h = inputs.positions, inputs.headings
        # One neighbour index per tick, shared by every sensor. (Balanced: unbalanced, it builds
        # faster but finds all pairs within a LiDAR's reach much slower, docs/speed.md.)
        tree = kd_tree(p) if inputs.tree is None else inputs.tree
        tick = inputs.tick
        sensing = Sensing(p, h, self.radii, self.heights, inputs.scene, tree,
                          lambda device, robots: self.streams[device].at(tick, robots), inputs.lights,
                          inputs.floor, self.camera_heights, self.half_windows, inputs.led_colors,
                          self._led_world(inputs), one_group=len(self.groups) == 1,
                          block=None if block == slice(0, self.n) else block)
        groups = []
        for g in self.groups:
            lo = min(max(g.robots.start, block.start), g.robots.stop)
            hi = max(lo, min(g.robots.stop, block.stop))
            # Rows within the block; a group outside it gets an empty slice.
            unread: dict = {}
            out = GroupReadings(g.model.name, slice(max(lo - block.start, 0), max(hi - block.start, 0)), unread)
            if hi > lo:
                for device in g.running:           # devices/: each reads the group into its fields, on first use
                    if device in GROUP_READERS:
                        # Called with the GroupReadings (not holding it: no reference cycle, so a
                        # frame and what its sensing holds go as soon as the frame does).
                        read = functools.partial(self._read, GROUP_READERS[device], sensing, g)
                        unread.update(dict.fromkeys(READINGS[device], read))
            groups.append(out)
        rab = None
        if self.rab_equipped.any():
            if not inputs.route_messages:       # nothing was sent before the first step
                rab = RangeAndBearingReadings.empty(block.stop - block.start, inputs.rab_payloads.shape[1])
            else:
                elevations = self.rab_elevations if inputs.altitudes is None else self.rab_elevations + inputs.altitudes
                rab = range_and_bearing(
                    p, h, self.radii, self.heights, self.rab_equipped, elevations, self.rab_ranges,
                    inputs.rab_payloads, inputs.scene, mode=self.world.range_and_bearing.mode,
                    check_occlusions=self.world.range_and_bearing.check_occlusions,
                    drop_probability=self.rab_drop, noise_std_m=self.rab_noise,
                    rng=self.streams[RANGE_AND_BEARING].at(tick, ()), tree=tree, receivers=block)
        ids = np.arange(block.start, block.stop)
        pose = positioning(p[block], h[block], position_noise_m=self.pose_noise[0][block],
                           yaw_noise_rad=self.pose_noise[1][block], rng=self.streams[POSITIONING].at(tick, ids),
                           altitudes=None if inputs.altitudes is None else inputs.altitudes[block])
        self.seconds += time.perf_counter() - t0
        info = None if inputs.supervisor_info is None else inputs.supervisor_info[block]
        return SensorFrame(tick, groups, pose, rows.wheels, rows.odometry, rows.odometry_twist, rab, info)

    def _read(self, reader, sensing: Sensing, group: SensedGroup, out: GroupReadings) -> None:
        t0 = time.perf_counter()
        reader(sensing, group, out)
        self.seconds += time.perf_counter() - t0

    def _led_world(self, inputs: SensingInputs):
        """(robots [l], leds [l]) → [l, 3]: where those LEDs are in the world frame. Only the LEDs
        a camera asks for (the lit ones) are placed: a worker's block reads a few hundred robots'
        cameras, and placing every LED of 10 000 robots would cost it more than its own sensing."""
        return functools.partial(leds_at, inputs.positions, inputs.headings, self.led_bodies)
