"""Which setpoint flies each drone: the firmware's commander, its priorities and its supervisor's
part in it, in arrays.

The commander keeps one setpoint and its priority per drone. Each tick the high-level commander
offers its setpoint (or motors off, when its planner is idle) at the lowest priority; a streamed
setpoint (full state, position, hover, world velocity, attitude and thrust) arrives at a higher
one. A setpoint is taken when its priority is at least the current one, and a streamed setpoint
taken also stops the high-level planner: from then on streams alone fly the drone, and the
high-level commander's offers are refused, until ``notify_setpoints_stop`` tells it the drone's
last state and lowers the priority again (its planner is then idle: without a new high-level
command the next tick's offer is motors off).

The supervisor's part: an emergency stop locks the drone (motors off, every command refused
until the simulation ends, as until a reboot); a setpoint older than 0.5 s while the motors run
makes the drone level out and hold its height, older than 2 s locks it.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.crazyflie.high_level import HighLevelCommander

# Setpoint kinds: what flies the drone this tick.
OFF, HIGH_LEVEL, FULL_STATE, POSITION, HOVER, VELOCITY, ATTITUDE, LEVEL_OUT = range(8)
KIND_NAMES = ("off", "high-level", "full-state", "position", "hover", "velocity", "attitude", "level-out")
# COMMANDER_PRIORITY_*: nothing yet (boot), the high-level commander, streamed setpoints.
PRIORITY_DISABLE, PRIORITY_HIGH_LEVEL, PRIORITY_STREAM = 0, 1, 2
WATCHDOG_LEVEL_OUT_S = 0.5              # supervisor.c COMMANDER_WDT_TIMEOUT_STABILIZE
WATCHDOG_SHUTDOWN_S = 2.0               # supervisor.c COMMANDER_WDT_TIMEOUT_SHUTDOWN
LEGACY_MIN_THRUST, LEGACY_MAX_THRUST = 1000, 60000     # crtp_commander_rpyt.c


class Setpoints:
    """Every drone's setpoint: ``kind`` [n]; position (hover: the height in z), velocity (hover:
    body-frame x, y), acceleration [n, 3], yaw, yaw rate [n] (rad, rad/s), body rates [n, 3],
    roll, pitch (rad) and thrust (0-60000) [n] of an attitude setpoint. The fields are views of
    one array, ``values`` [n, 17]."""

    COLUMNS = {"pos": slice(0, 3), "vel": slice(3, 6), "acc": slice(6, 9), "omega": slice(9, 12), "yaw": 12,
               "yaw_rate": 13, "roll": 14, "pitch": 15, "thrust": 16}
    WIDTH = 17
    FIELDS = tuple(COLUMNS)

    def __init__(self, n: int):
        self.kind = np.zeros(n, dtype=np.int8)
        self.values = np.zeros((n, self.WIDTH))

    def __getattr__(self, name: str):
        column = Setpoints.COLUMNS.get(name)
        if column is None:
            raise AttributeError(name)
        return self.values[:, column]

    def copy(self) -> "Setpoints":
        out = Setpoints(0)
        out.kind, out.values = self.kind.copy(), self.values.copy()
        return out


class Commander:
    def __init__(self, high_level: HighLevelCommander):
        n = self.n = high_level.n
        self.high_level = high_level
        self.current = Setpoints(n)
        self.priority = np.full(n, PRIORITY_DISABLE, dtype=np.int8)
        self.stamp = np.zeros(n)                 # when the current setpoint was taken (s)
        self.locked = np.zeros(n, dtype=bool)
        self.thrust_locked = np.ones(n, dtype=bool)   # legacy attitude setpoints: unlocked by a 0 thrust
        self.last_pos, self.last_vel, self.last_yaw = high_level.pos.copy(), np.zeros((n, 3)), high_level.yaw.copy()
        self.last_high_level = None      # the high-level commander's offers of the last tick

    def _offer(self, drones, t, priority: int, kind: int, **values) -> np.ndarray:
        """commanderSetSetpoint for ``drones``: taken where ``priority`` is at least theirs →
        the drones that took it (for a stream: their planners stop)."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        accepted = priority >= self.priority[drones]
        taken = drones[accepted]
        block = np.zeros((len(drones), Setpoints.WIDTH))
        for name, value in values.items():
            block[:, Setpoints.COLUMNS[name]] = value
        self.current.kind[taken] = kind
        self.current.values[taken] = block[accepted]
        self.priority[taken] = priority
        self.stamp[taken] = t
        if priority > PRIORITY_HIGH_LEVEL:
            self.high_level.stop(taken)
        return taken

    # --- streamed setpoints (the low-level topics) ------------------------------------------

    def full_state(self, drones, t, pos, vel, acc, yaw, omega) -> None:
        self._offer(drones, t, PRIORITY_STREAM, FULL_STATE, pos=pos, vel=vel, acc=acc, yaw=yaw, omega=omega)

    def position(self, drones, t, pos, yaw) -> None:
        self._offer(drones, t, PRIORITY_STREAM, POSITION, pos=pos, yaw=yaw)

    def hover(self, drones, t, vx, vy, yaw_rate, z) -> None:
        """Body-frame velocities (m/s), yaw rate (rad/s, counter-clockwise) and height (m)."""
        vx, vy, z = (np.asarray(v, dtype=np.float64) for v in (vx, vy, z))
        zero = np.zeros(np.broadcast(vx, vy, z).shape)
        self._offer(drones, t, PRIORITY_STREAM, HOVER, vel=np.stack([vx + zero, vy + zero, zero], axis=-1),
                    pos=np.stack([zero, zero, z + zero], axis=-1), yaw_rate=yaw_rate)

    def velocity(self, drones, t, vel, yaw_rate) -> None:
        """World-frame velocity (m/s) and yaw rate (rad/s, counter-clockwise)."""
        self._offer(drones, t, PRIORITY_STREAM, VELOCITY, vel=vel, yaw_rate=yaw_rate)

    def attitude(self, drones, t, roll, pitch, yaw_rate, thrust) -> None:
        """The legacy roll, pitch (rad), yaw rate (rad/s) and thrust (0-65535) setpoint: the thrust
        counts once a setpoint of thrust 0 has unlocked it, is 0 below 1000 and at most 60000.
        Angles as REP-103's (about x and y: a positive pitch accelerates along +x, a positive roll
        along -y; the yaw rate counter-clockwise): Crazyswarm2's ``cmd_vel_legacy`` gives degrees in
        the firmware's legacy frame, whose pitch is inverted and whose legacy yaw rate the firmware
        negates; converting is the caller's."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        thrust = np.broadcast_to(np.asarray(thrust, dtype=np.float64), drones.shape)
        self.thrust_locked[drones[(self.priority[drones] == PRIORITY_DISABLE)]] = True
        self.thrust_locked[drones[thrust == 0]] = False
        thrust = np.where(self.thrust_locked[drones] | (thrust < LEGACY_MIN_THRUST), 0.0,
                          np.minimum(thrust, LEGACY_MAX_THRUST))
        self._offer(drones, t, PRIORITY_STREAM, ATTITUDE, roll=roll, pitch=pitch, yaw_rate=yaw_rate, thrust=thrust)

    def notify_setpoints_stop(self, drones) -> None:
        """commanderRelaxPriority: the high-level commander told the state of the last tick, and
        its setpoints taken again."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        self.high_level.tell_state(drones, self.last_pos[drones], self.last_vel[drones], self.last_yaw[drones])
        self.priority[drones] = PRIORITY_HIGH_LEVEL

    # --- the supervisor ---------------------------------------------------------------------

    def emergency_stop(self, drones) -> None:
        """Motors off and every later command refused (the supervisor's lock)."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        self.locked[drones] = True
        self.high_level.block(drones, True)

    def disarm(self, drones) -> None:
        """A disarm request: the planner stops and the motors go off; the Crazyflie 2.1 arms itself
        again at once (it auto-arms), so later commands fly it again."""
        drones = np.atleast_1d(np.asarray(drones, dtype=np.int64))
        self.high_level.block(drones, True)
        self.high_level.block(drones[~self.locked[drones]], False)
        self.current.kind[drones] = OFF

    # --- per tick ---------------------------------------------------------------------------

    def step(self, t: float, state_pos, state_vel, state_yaw) -> Setpoints:
        """The stabilizer loop's commander part at ``t`` for every drone, from each one's state
        estimate → the setpoints that fly the drones (a view: copy what is kept)."""
        hl = self.last_high_level = self.high_level.setpoints(t, state_pos, state_vel, state_yaw)
        offering = np.flatnonzero(hl.given & ~self.locked)
        null = hl.null[offering]
        if null.any():
            self._offer(offering[null], t, PRIORITY_HIGH_LEVEL, OFF)
        flying = offering[~null]
        if len(flying):
            self._offer(flying, t, PRIORITY_HIGH_LEVEL, HIGH_LEVEL, pos=hl.pos[flying], vel=hl.vel[flying],
                        acc=hl.acc[flying], yaw=hl.yaw[flying], omega=hl.omega[flying],
                        yaw_rate=hl.omega[flying, 2])
        self.last_pos[:], self.last_vel[:], self.last_yaw[:] = state_pos, state_vel, state_yaw
        self._watchdog(t)
        self.current.kind[self.locked] = OFF
        return self.current

    def _watchdog(self, t: float) -> None:
        running = self.current.kind != OFF
        age = t - self.stamp
        expired = running & (age > WATCHDOG_SHUTDOWN_S)
        if expired.any():
            self.emergency_stop(np.flatnonzero(expired))
        cur = self.current
        stale = running & ~expired & (age > WATCHDOG_LEVEL_OUT_S) & (cur.kind != LEVEL_OUT)
        # supervisorOverrideSetpoint: x and y let go, roll and pitch level, yaw held, z as it was
        # (a height, or for a world velocity its vertical speed: NaN height).
        cur.roll[stale], cur.pitch[stale], cur.yaw_rate[stale] = 0.0, 0.0, 0.0
        stale &= cur.kind != ATTITUDE
        cur.pos[stale & (cur.kind == VELOCITY), 2] = np.nan
        cur.vel[stale, :2] = 0.0
        cur.kind[stale] = LEVEL_OUT
