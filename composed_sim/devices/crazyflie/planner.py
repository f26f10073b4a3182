"""The firmware's planner, one per drone, in arrays: its state machine and the trajectory it follows.

A drone's planner is idle (motors off: on the ground, or stopped), flying (following a trajectory,
then hovering at its end), landing (following a trajectory, then idle when it ends) or disabled
(a streamed setpoint has the drone; it offers nothing and wants the motors kept on). It follows
either its own one-piece plan (take-off, landing, go-to: a degree-7 polynomial from the current
state to the goal with zero jerk at both ends) or an uploaded trajectory (a run of pieces of the
drone's memory), started at ``t_begin`` with a timescale, possibly reversed, shifted and turned.

Every method takes the drones it acts on as an index array ``rows`` and values per row.
"""
from __future__ import annotations

import numpy as np

from composed_sim.devices.crazyflie import polynomials as poly
from composed_sim.devices.crazyflie.memory import TrajectoryMemory

IDLE, FLYING, LANDING, DISABLED = 0, 1, 3, 4        # enum trajectory_state
REFUSED = 1                                          # what plan_takeoff / plan_land return when refusing


class Planner:
    def __init__(self, n: int, memory: TrajectoryMemory):
        self.n = n
        self.memory = memory
        self.state = np.full(n, IDLE, dtype=np.int8)
        # The trajectory followed: the drone's own plan, or a run of its memory's pieces.
        self.in_memory = np.zeros(n, dtype=bool)
        self.first = np.zeros(n, dtype=np.int64)
        self.count = np.ones(n, dtype=np.int64)
        self.t_begin = np.zeros(n)
        self.timescale = np.ones(n)
        self.reversed = np.zeros(n, dtype=bool)
        self.shift = np.zeros((n, 3))
        self.shift_yaw = np.zeros(n)
        self.planned = np.zeros((n, 4, 8))
        self.planned_duration = np.zeros(n)

    # --- plans ---------------------------------------------------------------------------

    def _follow_plan(self, rows, coefficients, duration, t, state) -> None:
        self.planned[rows], self.planned_duration[rows] = coefficients, duration
        self.in_memory[rows], self.first[rows], self.count[rows] = False, 0, 1
        self.reversed[rows], self.shift[rows], self.shift_yaw[rows] = False, 0.0, 0.0
        self.t_begin[rows], self.timescale[rows] = t, 1.0
        self.state[rows] = state

    def takeoff_or_land(self, rows, t, landing: bool, pos, yaw, height, goal_yaw, duration) -> np.ndarray:
        """Straight up or down to ``height`` from ``pos`` [r, 3] while turning the shortest way to
        ``goal_yaw``. A take-off is refused unless idle, a landing while landing → codes [r]."""
        codes = np.zeros(len(rows), dtype=np.int64)
        refused = self.state[rows] == LANDING if landing else self.state[rows] != IDLE
        codes[refused] = REFUSED
        ok = ~refused
        rows, pos, yaw = rows[ok], pos[ok], yaw[ok]
        height, goal_yaw, duration = (np.broadcast_to(v, ok.shape)[ok] for v in (height, goal_yaw, duration))
        goal = pos.copy()
        goal[:, 2] = height
        start_yaw = poly.normalize_radians(yaw)
        end_yaw = start_yaw + poly.shortest_signed_angle(start_yaw, poly.normalize_radians(goal_yaw))
        zero3, zero = np.zeros((len(rows), 3)), np.zeros(len(rows))
        pieces = poly.plan_pieces(duration, pos, start_yaw, zero3, zero, zero3, goal, end_yaw, zero3, zero, zero3)
        self._follow_plan(rows, pieces, duration, t, LANDING if landing else FLYING)
        return codes

    def go_to_from(self, rows, t, current: poly.Evaluation, relative, linear, goal, goal_yaw, duration) -> None:
        """To ``goal`` [r, 3] and ``goal_yaw`` in ``duration`` from the state ``current`` (position,
        velocity, acceleration, yaw, body rates), smoothly or, ``linear``, at constant velocity."""
        relative, linear = (np.broadcast_to(v, (len(rows),)) for v in (relative, linear))
        goal = np.where(relative[:, None], goal + current.pos, goal)
        goal_yaw = np.where(relative, goal_yaw + current.yaw, goal_yaw)
        start_yaw = poly.normalize_radians(current.yaw)
        turn = poly.shortest_signed_angle(start_yaw, poly.normalize_radians(goal_yaw))
        duration = np.broadcast_to(np.asarray(duration, dtype=np.float64), (len(rows),))
        with np.errstate(divide="ignore", invalid="ignore"):
            line_vel = (goal - current.pos) / duration[:, None]
            line_rate = turn / duration
        zero3, zero = np.zeros((len(rows), 3)), np.zeros(len(rows))
        v0 = np.where(linear[:, None], line_vel, current.vel)
        w0 = np.where(linear, line_rate, current.omega[:, 2])
        a0 = np.where(linear[:, None], zero3, current.acc)
        v1, w1 = np.where(linear[:, None], line_vel, zero3), np.where(linear, line_rate, zero)
        pieces = poly.plan_pieces(duration, current.pos, start_yaw, v0, w0, a0, goal, start_yaw + turn, v1, w1, zero3)
        self._follow_plan(rows, pieces, duration, t, FLYING)

    def start_trajectory(self, rows, t, first, count, timescale, reversed_, relative, relative_yaw,
                         start_pos, start_yaw) -> None:
        """Follow ``count`` pieces of memory from ``first``, from ``t`` on; ``relative``: shifted so it
        starts at ``start_pos`` [r, 3] (and, ``relative_yaw``, turned to start at ``start_yaw``)."""
        self.in_memory[rows], self.first[rows], self.count[rows] = True, first, count
        self.t_begin[rows], self.timescale[rows] = t, timescale
        self.reversed[rows] = reversed_
        self.state[rows] = FLYING
        self.shift[rows], self.shift_yaw[rows] = 0.0, 0.0
        relative = np.broadcast_to(relative, (len(rows),))
        if relative.any():
            moved = rows[relative]
            begin = self.evaluate(moved, self.t_begin[moved])
            self.shift[moved] = np.asarray(start_pos)[relative] - begin.pos
            turn = np.broadcast_to(relative_yaw, (len(rows),))[relative]
            self.shift_yaw[moved[turn]] = poly.shortest_signed_angle(
                poly.normalize_radians(begin.yaw[turn]), poly.normalize_radians(np.asarray(start_yaw)[relative][turn]))

    def stop(self, rows) -> None:
        self.state[rows] = IDLE

    def disable(self, rows) -> None:
        self.state[rows] = DISABLED

    # --- where the trajectory is ---------------------------------------------------------

    def total_duration(self, rows) -> np.ndarray:
        """[r] each followed trajectory's duration, its timescale applied (piecewise_duration)."""
        in_memory = self.in_memory[rows]
        own = self.planned_duration[rows]
        if in_memory.any():
            own = np.where(in_memory, self.memory.total_duration(rows, self.first[rows], self.count[rows]), own)
        return own * self.timescale[rows]

    def current_goal(self, rows, t) -> poly.Evaluation:
        """plan_current_goal for drones that are flying or landing: a landing that has ended makes
        its drone idle (this evaluation is still its trajectory's end)."""
        landing = rows[self.state[rows] == LANDING]
        if len(landing):
            t_landing = np.broadcast_to(t, (len(rows),))[self.state[rows] == LANDING]
            ended = (t_landing - self.t_begin[landing]) >= self.total_duration(landing)
            self.state[landing[ended]] = IDLE
        return self.evaluate(rows, t)

    def _durations(self, rows, width: int) -> np.ndarray:
        """[r, width]: the durations of each trajectory's pieces 0 … width-1 (0 past its end)."""
        out = np.zeros((len(rows), width))
        out[:, 0] = self.planned_duration[rows]
        in_memory = self.in_memory[rows]
        if in_memory.any():
            memory_rows = rows[in_memory]
            slots = self.first[memory_rows, None] + np.arange(width)
            inside = slots < (self.first[memory_rows] + self.count[memory_rows])[:, None]
            last = self.memory.durations.shape[1] - 1
            durations = self.memory.durations[memory_rows[:, None], np.minimum(slots, last)]
            out[in_memory] = np.where(inside, durations, 0.0)
        return out

    def _piece_coefficients(self, rows, index) -> np.ndarray:
        out = self.planned[rows]
        in_memory = self.in_memory[rows]
        if in_memory.any():
            memory_rows = rows[in_memory]
            out[in_memory] = self.memory.coefficients[memory_rows, self.first[memory_rows] + index[in_memory]]
        return out

    def _find_pieces(self, rows, elapsed, durations):
        """Which piece each trajectory is in and the time within it, walking the pieces as the
        firmware does (subtracting each scaled duration in turn) → (piece, local time, found)."""
        count, scale, backwards = self.count[rows], self.timescale[rows], self.reversed[rows]
        piece = np.zeros(len(rows), dtype=np.int64)
        local = np.zeros(len(rows))
        found = np.zeros(len(rows), dtype=bool)
        remaining = np.array(elapsed, dtype=np.float64)
        every = np.arange(len(rows))
        for step in range(durations.shape[1]):
            index = np.where(backwards, count - 1 - step, step)
            span = durations[every, np.maximum(index, 0)] * scale
            searching = ~found & (step < count)
            hit = searching & (remaining <= span)
            piece[hit] = index[hit]
            local[hit] = np.where(backwards[hit], remaining[hit] - span[hit], remaining[hit])
            found |= hit
            remaining = np.where(searching & ~hit, remaining - span, remaining)
        return piece, local, found

    def evaluate(self, rows, t) -> poly.Evaluation:
        """piecewise_eval (or its reversed form) of each drone's trajectory at ``t``."""
        rows = np.asarray(rows)
        elapsed = np.broadcast_to(np.asarray(t, dtype=np.float64), (len(rows),)) - self.t_begin[rows]
        durations = self._durations(rows, int(self.count[rows].max(initial=1)))
        piece, local, found = self._find_pieces(rows, elapsed, durations)
        backwards = self.reversed[rows]
        ended_forward = ~found & ~backwards
        piece = np.where(ended_forward, self.count[rows] - 1, np.where(found, piece, 0))
        coefficients = self._piece_coefficients(rows, piece)
        shift, shift_yaw = self.shift[rows], self.shift_yaw[rows]
        going_back = found & backwards
        coefficients[going_back, :3, 0] += shift[going_back]
        coefficients = poly.stretch_time(coefficients, np.where(found, self.timescale[rows], 1.0))
        coefficients[going_back] = poly.reflect(coefficients[going_back])
        local = np.where(ended_forward, durations[np.arange(len(rows)), piece], np.where(found, local, 0.0))
        ev = poly.evaluate(coefficients, local)
        forward = np.flatnonzero(~backwards)
        poly.rotate_and_shift(ev, forward, shift[forward], shift_yaw[forward])
        ended_back = ~found & backwards
        ev.pos[ended_back] += shift[ended_back]
        for field in (ev.vel, ev.acc, ev.jerk, ev.omega):
            field[~found] = 0.0
        return ev
