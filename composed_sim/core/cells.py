"""The cells of the physics engine (core/cell_layout.py): one pymunk space each, stepped in turn.

Why cells: Chipmunk's solver sweeps every joint and contact of a space ``iterations`` times per
sub-step, 100 sweeps a tick here. A space of more than about 2000 robots no longer fits the
core's cache between sweeps, and each sweep then streams the robots from memory: the cost per
robot grows with the swarm (docs/speed.md, "Physics that scales"). Cells of about 1000 robots
stay in the cache.

A cell keeps its bodies from tick to tick (Chipmunk warm-starts contacts and joints from the
last step's impulses), in *slots*: each slot is one robot's body, circle, control body and
joints, built as core/physics.py builds them. At each tick boundary a cell takes the state of
every robot it simulates (its own and its ghosts) from the run's state arrays, steps, and gives
back its own robots' states. A slot whose robot leaves the cell's reach is parked far away
until a robot of the same model takes it: nothing is removed from a space, so the batch rows
stay in insertion order.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import pymunk
import pymunk.batch

from composed_sim.core.cell_layout import CellLayout
from composed_sim.core.physics import control_velocities, new_space, robot_bodies
from composed_sim.world.robot_models import RobotModel
from composed_sim.world.schema import World

_ALL = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
        | pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
STATE_FIELDS = 6     # a robot's state row: x, y, angle (unwrapped), vx, vy, w: pymunk.batch's order
# Parked slots wait here, 1 m apart: far from any arena, never touching one another.
_PARK_M = -1.0e6


class Cell:
    """One space: the robots of ``robots`` [k] (sorted) in slots, from the state rows [n, 6]."""

    def __init__(self, world: World, models: Sequence[RobotModel], robots: np.ndarray, state: np.ndarray):
        self.space = new_space(world)
        self._models = models
        self._substeps, self._dt = world.physics.substeps, world.tick_s / world.physics.substeps
        self.slot_robot = np.asarray(robots, dtype=np.int64).copy()   # [s] robot of each slot, -1: parked
        self._slot_model: list[str] = []
        # As core/physics.py: the robots with their joints first, then their control bodies, so a
        # cell of every robot is that space, body for body and joint for joint.
        controls = []
        for r in self.slot_robot.tolist():
            x, y, a = state[r, :3].tolist()
            body, shape, control, pivot, gear = robot_bodies(models[r], x, y, a)
            self.space.add(body, shape, pivot, gear)
            controls.append(control)
            self._slot_model.append(models[r].name)
        self.space.add(*controls)
        self._simulated = self.slot_robot.copy()    # [k] the robots simulated, sorted
        k = len(self.slot_robot)
        self._body_row = np.arange(k)                 # [s] batch row of each slot's body
        self._control_row = np.arange(k, 2 * k)       # [s] batch row of its control body
        # Two buffers: one that batch reads into, and one that points at the rows it sets from.
        self._buffer, self._set_buffer = pymunk.batch.Buffer(), pymunk.batch.Buffer()
        self._rows = self._read()
        self._index()

    def _read(self) -> np.ndarray:
        """[R, 6] every body of the space, in batch order (the static body last)."""
        self._buffer.clear()
        pymunk.batch.get_space_bodies(self.space, _ALL, self._buffer)
        return np.frombuffer(self._buffer.float_buf(), dtype=np.float64).reshape(-1, STATE_FIELDS).copy()

    def simulate(self, robots: np.ndarray) -> None:
        """From now on simulate exactly ``robots`` [k] (sorted): park the slots of those that left,
        give the others a slot (a parked one of their model, else a new one)."""
        if np.array_equal(robots, self._simulated):
            return
        self._simulated = robots
        self.slot_robot[~_within(self.slot_robot, robots)] = -1
        for r in robots[~_within(robots, np.sort(self.slot_robot))].tolist():
            name = self._models[r].name
            free = [s for s in np.flatnonzero(self.slot_robot < 0).tolist() if self._slot_model[s] == name]
            if free:
                self.slot_robot[free[0]] = r
            else:
                self._add_slot(r)
        # A parked body keeps its rows: at rest, far from everything, its control body still.
        parked = np.flatnonzero(self.slot_robot < 0)
        self._rows[self._body_row[parked]] = 0.0
        self._rows[self._body_row[parked], 0] = _PARK_M + parked
        self._rows[self._body_row[parked], 1] = _PARK_M
        self._rows[self._control_row[parked], 3:6] = 0.0
        self._index()

    def _index(self) -> None:
        """The batch rows of the simulated robots' bodies and control bodies, in robot order."""
        slot = np.flatnonzero(self.slot_robot >= 0)
        slot = slot[np.argsort(self.slot_robot[slot])]
        self._body_rows, self._control_rows = self._body_row[slot], self._control_row[slot]

    def _add_slot(self, robot: int) -> None:
        body, shape, control, pivot, gear = robot_bodies(self._models[robot], _PARK_M, _PARK_M, 0.0)
        self.space.add(body, shape, pivot, gear, control)
        # The space's bodies: the old dynamic ones, this body, its control body; then the static body.
        rows = len(self._rows) - 1
        self._body_row = np.append(self._body_row, rows)
        self._control_row = np.append(self._control_row, rows + 1)
        self.slot_robot = np.append(self.slot_robot, robot)
        self._slot_model.append(self._models[robot].name)
        self._rows = self._read()

    def step(self, state: np.ndarray, control: np.ndarray) -> None:
        """One tick of the cell's robots from their state rows [n, 6] and control velocities [n, 3]."""
        rows, robots = self._rows, self._simulated
        rows[self._body_rows] = state[robots]
        rows[self._control_rows, 3:6] = control[robots]
        self._set_buffer.set_float_buf(rows)
        pymunk.batch.set_space_bodies(self.space, _ALL, self._set_buffer)
        step, dt = self.space.step, self._dt
        for _ in range(self._substeps):
            step(dt)
        self._rows = self._read()

    def states(self, robots: np.ndarray) -> np.ndarray:
        """[k, 6] the states after the last step of ``robots`` [k], each simulated here."""
        return self._rows[self._body_rows[np.searchsorted(self._simulated, robots)]]


class CellGroup:
    """The cells ``mine`` of ``layout``, stepped one after the other: a region's share of a tick."""

    def __init__(self, world: World, models: Sequence[RobotModel], layout: CellLayout, mine: Sequence[int],
                 state: np.ndarray):
        self.layout, self.mine = layout, list(mine)
        self._wheel_separation_m = np.array([m.wheel_separation_m for m in models], dtype=np.float64)
        owner = layout.owners(state[:, :2])
        cell, robot = layout.members(state[:, :2], owner)
        self.cells = [Cell(world, models, _of_cell(cell, robot, c), state) for c in self.mine]

    def step(self, state: np.ndarray, left_mps: np.ndarray, right_mps: np.ndarray, out: np.ndarray) -> None:
        """One tick from ``state`` [n, 6] and the wheel speeds [n] each: the rows of the robots
        these cells own, written into ``out`` [n, 6]."""
        # Over every robot at once, the very call core/physics.py makes: a robot's control velocity
        # is the one space's, bit for bit, whichever cell steps it.
        control = control_velocities(left_mps, right_mps, self._wheel_separation_m, state[:, 2])
        owner = self.layout.owners(state[:, :2])
        cell, robot = self.layout.members(state[:, :2], owner)
        for c, space in zip(self.mine, self.cells):
            robots = _of_cell(cell, robot, c)
            space.simulate(robots)
            owned = robots[owner[robots] == c]
            if len(robots):
                space.step(state, control)
                out[owned] = space.states(owned)


def _within(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """[k] whether each of ``values`` [k] is in ``sorted_set`` (sorted; np.isin is slower here)."""
    if not len(sorted_set):
        return np.zeros(len(values), dtype=bool)
    at = np.minimum(np.searchsorted(sorted_set, values), len(sorted_set) - 1)
    return sorted_set[at] == values


def _of_cell(cell: np.ndarray, robot: np.ndarray, c: int) -> np.ndarray:
    """The robots of cell ``c`` from (cell, robot) pairs sorted by cell."""
    return robot[np.searchsorted(cell, c, side="left"):np.searchsorted(cell, c, side="right")]
