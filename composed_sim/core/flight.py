"""The drones of a world: robots whose model flies (world/robot_models.py's ``flight``).

They are not bodies of the 2D physics: every tick their firmware (devices/crazyflie's
``Crazyflies``: high-level commander, commander, supervisor) computes each drone's setpoint and
the drone moves under it, by default exactly as Crazyswarm2's ``none`` backend does (the world
file's ``flight.tracking`` adds a lag). Their x, y and yaw are the run's positions and headings,
like every robot's, so the devices that read poses read them; their altitude is the run's
``altitudes`` (0 for a robot on wheels). They start on the floor.

For the layer that commands them (a ROS server, a test), ``Drones`` maps robot indices to drone
indices (``of_robots``) and gives the fleet (``fleet``) whose commands take a drone index and
the time the command arrives (``now``); the hosts hand it each tick's records of the drones'
Crazyswarm2 services and setpoint topics (``apply``, core/drone_commands.py).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from composed_sim.core.drone_commands import DroneCommand, DroneCommander, Refusal
from composed_sim.core.near_misses import NearMisses
from composed_sim.devices.crazyflie import Crazyflies, Tracking
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import World


class Drones:
    def __init__(self, world: World, models: Sequence[RobotModel], positions: np.ndarray, headings: np.ndarray):
        self.robots = np.flatnonzero([m.flies for m in models])          # [d] their robot indices
        self._drone_of = np.full(len(models), -1, dtype=np.int64)
        self._drone_of[self.robots] = np.arange(len(self.robots))
        masses = {models[r].mass_kg for r in self.robots}
        if len(masses) > 1:
            raise ValueError(f"one fleet of drones has one mass; these models differ: {sorted(masses)}")
        flight = world.flight
        tracking = None if flight.tracking is None else Tracking(flight.tracking.order,
                                                                 flight.tracking.time_constant_s)
        start = np.column_stack([positions[self.robots], np.zeros(len(self.robots))])
        self.fleet = Crazyflies(start, headings[self.robots], mass_kg=masses.pop() if masses else 0.0,
                                tracking=tracking)
        self.near_misses = NearMisses(self.robots, flight.near_miss_radius_m, flight.near_miss_height_ratio)
        self.tick_s = world.tick_s
        self.tick = 0
        self.commander = DroneCommander(self.fleet, self._drone_of, _arena_test(world))

    @property
    def now(self) -> float:
        """The simulation's time (s): a command arriving during the current tick acts from it."""
        return self.tick * self.tick_s

    def of_robots(self, robots) -> np.ndarray:
        """Robot indices → drone indices (a robot that does not fly: an IndexError naming it)."""
        robots = np.atleast_1d(np.asarray(robots, dtype=np.int64))
        drones = self._drone_of[robots]
        if (drones < 0).any():
            raise IndexError(f"robots {robots[drones < 0].tolist()} do not fly")
        return drones

    def apply(self, commands: Sequence[DroneCommand]) -> list[Refusal]:
        """A tick's commands (core/drone_commands.py), arriving now: what was refused."""
        return self.commander.apply(commands, self.now) if commands else []

    def supervisor_info(self) -> np.ndarray:
        """[d] uint16: each drone's Status.supervisor_info bits."""
        return self.fleet.supervisor_info()

    def advance(self, tick: int) -> None:
        """Step ``tick``: each drone's firmware at the step's end time, from the state before it,
        and each drone moved there; the near misses of the new poses counted."""
        self.tick = tick
        self.fleet.advance(self.now, self.tick_s)
        state = self.fleet.state
        self.near_misses.check(tick, state.pos[:, :2], state.pos[:, 2])

    def place(self, positions: np.ndarray, headings: np.ndarray, altitudes: np.ndarray) -> None:
        """Write the drones' poses into the run's arrays (every robot's, [n, 2], [n], [n])."""
        state = self.fleet.state
        positions[self.robots] = state.pos[:, :2]
        headings[self.robots] = state.yaw
        altitudes[self.robots] = state.pos[:, 2]


def _arena_test(world: World):
    """``inside(xy [d, 2]) → [d] bool`` for the world's arena (everywhere, for one without a size)."""
    arena = world.arena
    if arena.size is None:
        return lambda xy: np.ones(len(xy), dtype=bool)
    center, half = np.asarray(arena.center, dtype=np.float64), np.asarray(arena.size, dtype=np.float64) / 2
    return lambda xy: (np.abs(np.asarray(xy) - center) <= half).all(axis=1)
