"""The firmware's high-level commander, one per drone, in arrays (crtp_commander_high_level's rules).

Commands are addressed to some drones (``drones``: an index array) with the command's group
mask: a drone obeys a mask of 0 (all groups) or one sharing a bit with its own group mask, and
ignores the others (answering 0, as the firmware does). A drone the supervisor blocks (locked
after an emergency stop) answers EBUSY to everything but ``stop``. What the planner refuses it
answers with the planner's 1 (a take-off while not idle, a landing while landing).

The commander remembers its last setpoint (position, velocity, yaw): new plans start from it
while flying; while idle or disabled it is the drone's state estimate, read every tick.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.crazyflie import polynomials as poly
from composed_sim.devices.crazyflie.memory import TrajectoryMemory
from composed_sim.devices.crazyflie.planner import DISABLED, FLYING, IDLE, LANDING, Planner

EBUSY = 16                     # errno: blocked by the supervisor
ALL_GROUPS = 0
DEFAULT_TAKEOFF_VELOCITY_MPS = 0.5       # hlCommander.vtoff
DEFAULT_LANDING_VELOCITY_MPS = 0.5       # hlCommander.vland


class HighLevelSetpoints:
    """One tick of every drone's high-level commander: ``given`` [n] (it has a setpoint to
    offer), ``null`` [n] (that setpoint is motors off: the planner is idle), and for the others
    the trajectory's position, velocity, acceleration [n, 3], yaw [n] and body rates [n, 3]."""

    __slots__ = ("given", "null", "pos", "vel", "acc", "yaw", "omega")

    def __init__(self, n: int):
        self.given, self.null = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        self.pos, self.vel, self.acc = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
        self.yaw, self.omega = np.zeros(n), np.zeros((n, 3))


class HighLevelCommander:
    def __init__(self, n: int, pos=None, yaw=None):
        self.n = n
        self.memory = TrajectoryMemory(n)
        self.planner = Planner(n, self.memory)
        self.group_mask = np.zeros(n, dtype=np.uint8)
        self.blocked = np.zeros(n, dtype=bool)
        # The last setpoint (or, while idle or disabled, the state estimate).
        self.pos = np.zeros((n, 3)) if pos is None else np.array(pos, dtype=np.float64).reshape(n, 3)
        self.vel = np.zeros((n, 3))
        self.yaw = np.zeros(n) if yaw is None else np.array(yaw, dtype=np.float64).reshape(n)

    # --- addressing ----------------------------------------------------------------------

    def _addressed(self, drones, group_mask: int, *, blockable: bool = True):
        """(codes [d], obeying [d] bool): EBUSY where blocked; who obeys the mask."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        codes = np.zeros(len(drones), dtype=np.int64)
        busy = self.blocked[drones] if blockable else np.zeros(len(drones), dtype=bool)
        codes[busy] = EBUSY
        mask = np.uint8(group_mask)
        member = (mask == ALL_GROUPS) | ((self.group_mask[drones] & mask) != 0)
        return drones, codes, ~busy & member

    @staticmethod
    def _per_drone(value, obeying: np.ndarray, shape=()) -> np.ndarray:
        """A scalar or a per-addressed-drone value, for the obeying drones."""
        value = np.asarray(value, dtype=np.float64)
        return np.broadcast_to(value, obeying.shape + shape)[obeying]

    def _stopped_or_disabled(self, rows) -> np.ndarray:
        state = self.planner.state[rows]
        return (state == IDLE) | (state == DISABLED)

    # --- commands ------------------------------------------------------------------------

    def takeoff(self, drones, t, height, duration, yaw=None, group_mask=ALL_GROUPS, landing=False):
        """Up (or, ``landing``, down) to ``height`` m in ``duration`` s, turning to ``yaw`` (None:
        keep the current yaw) → codes [d]."""
        drones, codes, obey = self._addressed(drones, group_mask)
        rows = drones[obey]
        goal_yaw = self.yaw[rows] if yaw is None else self._per_drone(yaw, obey)
        codes[obey] = self.planner.takeoff_or_land(rows, t, landing, self.pos[rows], self.yaw[rows],
                                                   self._per_drone(height, obey), goal_yaw,
                                                   self._per_drone(duration, obey))
        return codes

    def land(self, drones, t, height, duration, yaw=None, group_mask=ALL_GROUPS):
        return self.takeoff(drones, t, height, duration, yaw, group_mask, landing=True)

    def takeoff_with_velocity(self, drones, t, height, velocity, relative=False, yaw=None,
                              group_mask=ALL_GROUPS, landing=False):
        """As ``takeoff``/``land``, its duration from an average ``velocity`` (≤ 0: the default,
        0.5 m/s); ``relative``: ``height`` up from (or, landing, down from) the current height."""
        drones, codes, obey = self._addressed(drones, group_mask)
        rows = drones[obey]
        z = self.pos[rows, 2]
        height = self._per_drone(height, obey)
        relative = np.broadcast_to(relative, obey.shape)[obey]
        height = np.where(relative, z - height if landing else height + z, height)
        velocity = self._per_drone(velocity, obey)
        default = DEFAULT_LANDING_VELOCITY_MPS if landing else DEFAULT_TAKEOFF_VELOCITY_MPS
        duration = np.abs(height - z) / np.where(velocity > 0, velocity, default)
        goal_yaw = self.yaw[rows] if yaw is None else self._per_drone(yaw, obey)
        codes[obey] = self.planner.takeoff_or_land(rows, t, landing, self.pos[rows], self.yaw[rows], height,
                                                   goal_yaw, duration)
        return codes

    def go_to(self, drones, t, goal, yaw, duration, relative=False, linear=False, group_mask=ALL_GROUPS):
        """To ``goal`` (m, [3] or [d, 3]) and ``yaw`` (rad) in ``duration`` s; ``relative``: from
        the current setpoint; ``linear``: at constant velocity → codes [d]."""
        drones, codes, obey = self._addressed(drones, group_mask)
        rows = drones[obey]
        still = self._stopped_or_disabled(rows)
        current = poly.Evaluation(self.pos[rows], self.vel[rows], np.zeros((len(rows), 3)), np.zeros((len(rows), 3)),
                                  self.yaw[rows], np.zeros((len(rows), 3)))
        moving = np.flatnonzero(~still)
        if len(moving):
            goal_now = self.planner.current_goal(rows[moving], t)
            for field in current.__slots__:
                getattr(current, field)[moving] = getattr(goal_now, field)
        self.planner.go_to_from(rows, t, current, np.broadcast_to(relative, obey.shape)[obey],
                                np.broadcast_to(linear, obey.shape)[obey], self._per_drone(goal, obey, (3,)),
                                self._per_drone(yaw, obey), self._per_drone(duration, obey))
        return codes

    def start_trajectory(self, drones, t, trajectory_id: int, timescale=1.0, reversed=False, relative=False,
                         relative_yaw=False, group_mask=ALL_GROUPS):
        """Follow uploaded trajectory ``trajectory_id`` from ``t`` → codes [d]; an id a drone has
        not defined is ignored (0), as by the firmware."""
        drones, codes, obey = self._addressed(drones, group_mask)
        obey &= self.memory.is_defined(drones, trajectory_id)
        rows = drones[obey]
        if len(rows):
            self.planner.start_trajectory(rows, t, self.memory.offset[rows, trajectory_id],
                                          self.memory.n_pieces[rows, trajectory_id],
                                          self._per_drone(timescale, obey), reversed, relative, relative_yaw,
                                          self.pos[rows], self.yaw[rows])
        return codes

    def stop(self, drones, group_mask=ALL_GROUPS):
        """Planner idle: motors off → codes [d] (never EBUSY)."""
        drones, codes, obey = self._addressed(drones, group_mask, blockable=False)
        self.planner.stop(drones[obey])
        return codes

    def upload_trajectory(self, drones, trajectory_id: int, piece_offset: int, coefficients, durations):
        """Pieces [p, 4, 8] (x, y, z, yaw; ascending degree) with durations [p] written at
        ``piece_offset`` and defined as ``trajectory_id`` → codes [d] (memory.py's)."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        codes = self.memory.write(drones, piece_offset, coefficients, durations)
        written = drones[codes == 0]
        codes[codes == 0] = self.memory.define(written, trajectory_id, piece_offset, len(np.atleast_1d(durations)))
        return codes

    def set_group_mask(self, drones, group_mask: int) -> None:
        self.group_mask[np.atleast_1d(drones)] = np.uint8(group_mask)

    # --- the hand-over with streamed setpoints and the supervisor -------------------------

    def tell_state(self, drones, pos, vel, yaw) -> None:
        """crtpCommanderHighLevelTellState: plans start from this state from now on."""
        self.pos[drones], self.vel[drones], self.yaw[drones] = pos, vel, yaw

    def disable(self, drones) -> None:
        self.planner.disable(np.atleast_1d(drones))

    def block(self, drones, blocked: bool) -> None:
        """crtpCommanderBlock: a drone newly blocked while following a trajectory stops."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        if blocked:
            newly = drones[~self.blocked[drones] & ~self._stopped_or_disabled(drones)]
            self.planner.stop(newly)
        self.blocked[drones] = blocked

    # --- per tick ------------------------------------------------------------------------

    def setpoints(self, t: float, state_pos, state_vel, state_yaw) -> HighLevelSetpoints:
        """crtpCommanderHighLevelGetSetpoint for every drone at ``t``, given each one's state
        estimate (position, velocity [n, 3], yaw [n])."""
        out = HighLevelSetpoints(self.n)
        state = self.planner.state
        following = np.flatnonzero((state == FLYING) | (state == LANDING))
        ev = self.planner.current_goal(following, t) if len(following) else None
        still = (state == IDLE) | (state == DISABLED)
        self.pos[still], self.vel[still], self.yaw[still] = state_pos[still], state_vel[still], state_yaw[still]
        out.null[:] = state == IDLE
        out.given[:] = out.null
        if ev is not None:
            keep = ~still[following]
            rows = following[keep]
            out.given[rows] = True
            for field in ("pos", "vel", "acc", "yaw", "omega"):
                getattr(out, field)[rows] = getattr(ev, field)[keep]
            self.pos[rows], self.vel[rows], self.yaw[rows] = out.pos[rows], out.vel[rows], out.yaw[rows]
        return out
