"""A swarm of Crazyflies: every drone's firmware (high-level commander, commander, supervisor)
and its motion, in arrays over the drones; what the simulation steps and a ROS layer commands.

Drones are numbered 0 … n-1 here; ``drones`` in a command is an int, a sequence or array of them,
a slice, or None (all). A command acts at time ``t`` (s, the simulation's clock when it arrives)
and answers a code per addressed drone: 0; 1 (refused by the planner: a take-off while not idle,
a landing while landing); 16 (EBUSY: locked by an emergency stop); 8 (ENOEXEC: a trajectory id
the table does not have); or 1 for an upload that does not fit the memory (see memory.py).
A command with a group mask that a drone is not in is ignored by it and answers 0 (``in_group``
tells who obeys a mask). A command's numbers must be finite: anything else is a ValueError naming
the argument, before any drone is touched.

Each tick, ``advance(t, dt)`` runs every drone's stabilizer loop at ``t`` (the setpoints, from the
state before the tick) and moves the drones to ``t`` under them (motion.py); the high-level
commander runs at every tick (the firmware's runs at 100 Hz).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from composed_sim.devices.crazyflie import motion
from composed_sim.devices.crazyflie.commander import OFF, Commander, Setpoints
from composed_sim.devices.crazyflie.high_level import ALL_GROUPS, HighLevelCommander
from composed_sim.devices.crazyflie.planner import FLYING, LANDING

# Status.supervisor_info bits (crazyflie_interfaces/Status, the firmware's supervisor.info).
CAN_BE_ARMED, IS_ARMED, AUTO_ARM, CAN_FLY, IS_FLYING, IS_TUMBLED, IS_LOCKED = 1, 2, 4, 8, 16, 32, 64


class Crazyflies:
    def __init__(self, positions, yaws, *, mass_kg: float, tracking: Optional[motion.Tracking] = None,
                 battery_voltage_v: float = 4.2):
        self.state = motion.DroneState(positions, yaws)
        self.n = len(self.state.yaw)
        self.high_level = HighLevelCommander(self.n, self.state.pos, self.state.yaw)
        self.commander = Commander(self.high_level)
        self.mass_kg = mass_kg
        self.tracking = tracking
        self.battery_voltage_v = battery_voltage_v
        self.setpoints = Setpoints(self.n)     # what flew each drone in the last tick

    @staticmethod
    def _finite(**values) -> None:
        for name, value in values.items():
            if value is not None and not np.isfinite(np.asarray(value, dtype=np.float64)).all():
                raise ValueError(f"{name} must be finite, got {value!r}")

    def in_group(self, drones, group_mask: int) -> np.ndarray:
        """[d] bool: which of ``drones`` obey a command with ``group_mask`` (0: all)."""
        rows = self._rows(drones)
        return (group_mask == ALL_GROUPS) | ((self.high_level.group_mask[rows] & np.uint8(group_mask)) != 0)

    def _rows(self, drones) -> np.ndarray:
        if drones is None:
            return np.arange(self.n)
        if isinstance(drones, slice):
            return np.arange(self.n)[drones]
        rows = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        if rows.size and (rows.min() < 0 or rows.max() >= self.n):
            raise IndexError(f"drone index out of range 0..{self.n - 1}: {rows.tolist()}")
        return rows

    # --- high-level commands (the services) -------------------------------------------------

    def takeoff(self, drones, t, height, duration, *, yaw=None, group_mask=ALL_GROUPS):
        self._finite(t=t, height=height, duration=duration, yaw=yaw)
        return self.high_level.takeoff(self._rows(drones), t, height, duration, yaw, group_mask)

    def land(self, drones, t, height, duration, *, yaw=None, group_mask=ALL_GROUPS):
        self._finite(t=t, height=height, duration=duration, yaw=yaw)
        return self.high_level.land(self._rows(drones), t, height, duration, yaw, group_mask)

    def takeoff_with_velocity(self, drones, t, height, velocity, *, relative=False, yaw=None, group_mask=ALL_GROUPS):
        self._finite(t=t, height=height, velocity=velocity, yaw=yaw)
        return self.high_level.takeoff_with_velocity(self._rows(drones), t, height, velocity, relative, yaw,
                                                     group_mask)

    def land_with_velocity(self, drones, t, height, velocity, *, relative=False, yaw=None, group_mask=ALL_GROUPS):
        self._finite(t=t, height=height, velocity=velocity, yaw=yaw)
        return self.high_level.takeoff_with_velocity(self._rows(drones), t, height, velocity, relative, yaw,
                                                     group_mask, landing=True)

    def go_to(self, drones, t, goal, yaw, duration, *, relative=False, linear=False, group_mask=ALL_GROUPS):
        self._finite(t=t, goal=goal, yaw=yaw, duration=duration)
        return self.high_level.go_to(self._rows(drones), t, goal, yaw, duration, relative, linear, group_mask)

    def upload_trajectory(self, drones, trajectory_id, piece_offset, coefficients, durations):
        self._finite(coefficients=coefficients, durations=durations)
        return self.high_level.upload_trajectory(self._rows(drones), trajectory_id, piece_offset, coefficients,
                                                 durations)

    def start_trajectory(self, drones, t, trajectory_id, *, timescale=1.0, reversed=False, relative=False,
                         relative_yaw=False, group_mask=ALL_GROUPS):
        self._finite(t=t, timescale=timescale)
        return self.high_level.start_trajectory(self._rows(drones), t, trajectory_id, timescale, reversed,
                                                relative, relative_yaw, group_mask)

    def stop(self, drones, *, group_mask=ALL_GROUPS):
        return self.high_level.stop(self._rows(drones), group_mask)

    def set_group_mask(self, drones, group_mask: int) -> None:
        self.high_level.set_group_mask(self._rows(drones), group_mask)

    def notify_setpoints_stop(self, drones) -> None:
        self.commander.notify_setpoints_stop(self._rows(drones))

    def emergency(self, drones) -> None:
        self.commander.emergency_stop(self._rows(drones))

    def arm(self, drones, arm: bool) -> None:
        if not arm:
            self.commander.disarm(self._rows(drones))

    # --- streamed setpoints (the low-level topics) -------------------------------------------

    def cmd_full_state(self, drones, t, pos, vel, acc, yaw, omega) -> None:
        self._finite(t=t, pos=pos, vel=vel, acc=acc, yaw=yaw, omega=omega)
        self.commander.full_state(self._rows(drones), t, pos, vel, acc, yaw, omega)

    def cmd_position(self, drones, t, pos, yaw) -> None:
        self._finite(t=t, pos=pos, yaw=yaw)
        self.commander.position(self._rows(drones), t, pos, yaw)

    def cmd_hover(self, drones, t, vx, vy, yaw_rate, z) -> None:
        self._finite(t=t, vx=vx, vy=vy, yaw_rate=yaw_rate, z=z)
        self.commander.hover(self._rows(drones), t, vx, vy, yaw_rate, z)

    def cmd_velocity_world(self, drones, t, vel, yaw_rate) -> None:
        self._finite(t=t, vel=vel, yaw_rate=yaw_rate)
        self.commander.velocity(self._rows(drones), t, vel, yaw_rate)

    def cmd_attitude(self, drones, t, roll, pitch, yaw_rate, thrust) -> None:
        self._finite(t=t, roll=roll, pitch=pitch, yaw_rate=yaw_rate, thrust=thrust)
        self.commander.attitude(self._rows(drones), t, roll, pitch, yaw_rate, thrust)

    # --- per tick ----------------------------------------------------------------------------

    def advance(self, t: float, dt: float) -> None:
        """The firmware at ``t`` from the state at ``t - dt``, then the drones moved to ``t``."""
        s = self.state
        self.setpoints = self.commander.step(t, s.pos, s.vel, s.yaw)
        motion.advance(s, self.setpoints, dt, self.mass_kg, self.tracking)

    @property
    def heights(self) -> np.ndarray:
        return self.state.pos[:, 2]

    def supervisor_info(self) -> np.ndarray:
        """[n] uint16 Status.supervisor_info: auto-armed and armed, can fly unless locked, flying
        while the motors run, locked after an emergency stop."""
        locked = self.commander.locked
        info = np.full(self.n, AUTO_ARM | IS_ARMED, dtype=np.uint16)
        info[~locked] |= CAN_FLY
        info[locked] = (info[locked] & ~np.uint16(IS_ARMED)) | IS_LOCKED
        info[(self.setpoints.kind != OFF) & ~locked] |= IS_FLYING
        return info

    def planner_states(self) -> np.ndarray:
        return self.high_level.planner.state.copy()

    def following_trajectory(self) -> np.ndarray:
        """[n] bool: the planner is flying or landing."""
        state = self.high_level.planner.state
        return (state == FLYING) | (state == LANDING)
