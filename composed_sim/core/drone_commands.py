"""What the drones' Crazyswarm2 services and setpoint topics were told in a tick, as records, and
those records applied to the firmware of the swarm (devices/crazyflie's ``Crazyflies``).

The ROS side (ros/crazyflie/) turns each service call and setpoint message into a ``DroneCommand``
wherever the drone's endpoints are hosted; the host carries the tick's records to the main
process, which applies them here at the tick's close, before the step: one order in every host
mode, whatever process took them (docs/crazyflie.md):

- first the swarm's commands (the ``crazyflie_server``'s ``all/*``, ``robot`` = ALL), then drone by
  drone in robot order, each drone's in the order they arrived (``stamp_ns``, then ``seq``);
- drones are independent of one another, so the k-th command of every drone is applied together,
  one firmware call per kind (vectorised over the drones that got one): a drone that got nothing
  costs nothing.

What the firmware refuses (a take-off while flying, anything after an emergency stop, an
undefined trajectory id) and what no drone should be asked (a go-to outside the arena, a
trajectory with no pieces or a piece of non-positive duration, a non-finite number) changes
nothing and comes back as a ``Refusal``, which the host logs as a warning, as Crazyswarm2's server
logs what it cannot do.
"""
from __future__ import annotations

from typing import NamedTuple, Optional, Sequence

import numpy as np

from composed_sim.devices.crazyflie import Crazyflies
from composed_sim.devices.crazyflie.high_level import EBUSY
from composed_sim.devices.crazyflie.memory import ENOEXEC, PIECE_SLOTS

ALL = -1      # ``robot`` of a command for every drone (a group mask may pick some)

# What each kind's ``args`` are (units SI, angles rad, counter-clockwise):
HIGH_LEVEL = {
    "takeoff": ("height", "duration", "group_mask"),
    "land": ("height", "duration", "group_mask"),
    "go_to": ("x", "y", "z", "yaw", "duration", "relative", "group_mask"),
    "start_trajectory": ("trajectory_id", "timescale", "reversed", "relative", "group_mask"),
    "upload_trajectory": ("trajectory_id", "piece_offset", "coefficients [p, 4, 8]", "durations [p]"),
    "notify_setpoints_stop": ("remain_valid_ms", "group_mask"),
    "stop": ("group_mask",),
    "emergency": (),
    "arm": ("arm",),
    "set_group_mask": ("group_mask",),
}
STREAMS = {
    "full_state": ("x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "yaw", "wx", "wy", "wz"),
    "position": ("x", "y", "z", "yaw"),
    "hover": ("vx", "vy", "yaw_rate", "z"),
    "velocity_world": ("vx", "vy", "vz", "yaw_rate"),
    "attitude": ("roll", "pitch", "yaw_rate", "thrust"),
}
KINDS = {**HIGH_LEVEL, **STREAMS}


class DroneCommand(NamedTuple):
    """One service call or setpoint message for a drone (``robot``: its index in the run) or for
    all (ALL); ordered by (robot, stamp_ns, seq)."""
    robot: int
    stamp_ns: int          # when it reached the simulator's side (wall clock ns)
    seq: int               # ties, in the order taken
    kind: str              # a key of KINDS
    args: tuple


class Refusal(NamedTuple):
    robot: int             # ALL: a command for the swarm
    text: str


UNDEFINED = -1        # our code: a start of a trajectory the drone has not defined, which the firmware ignores
_CODES = {UNDEFINED: "ignored: the drone has no such trajectory defined (the firmware ignores it too)",
          1: "refused by the planner", EBUSY: "refused: the drone is locked after an emergency stop (EBUSY)",
          ENOEXEC: "refused: no such trajectory id (ENOEXEC)"}
_PLANNER = {"takeoff": "a take-off while the planner is not idle (flying, or not landed yet)",
            "land": "a landing while landing", "upload_trajectory": "the pieces do not fit the trajectory memory "
            f"({PIECE_SLOTS} pieces)"}


class DroneCommander:
    """Applies a tick's commands to ``fleet``; ``drone_of`` [n] maps a robot index to its drone
    index; ``inside(xy [d, 2]) → [d] bool``: which points are inside the arena."""

    def __init__(self, fleet: Crazyflies, drone_of: np.ndarray, inside=lambda xy: np.ones(len(xy), dtype=bool)):
        self.fleet = fleet
        self._drone_of = drone_of
        self._robot_of = np.flatnonzero(drone_of >= 0)
        self._inside = inside

    def apply(self, commands: Sequence[DroneCommand], now: float) -> list[Refusal]:
        """The tick's commands, arriving at ``now`` (s), in the one order (module docstring)."""
        refusals: list[Refusal] = []
        ordered = sorted(commands)
        everyone = np.arange(self.fleet.n)
        for command in ordered:
            if command.robot == ALL:
                self._apply(command.kind, everyone, [command], self._robot_of, now, refusals)
        ranks: list[dict] = []          # rank k → (kind, key) → the drones' k-th commands
        previous, rank = None, 0
        for command in ordered:
            if command.robot == ALL:
                continue
            rank = rank + 1 if command.robot == previous else 0
            previous = command.robot
            if rank == len(ranks):
                ranks.append({})
            ranks[rank].setdefault(_batch_key(command), []).append(command)
        for batches in ranks:
            for batch in batches.values():
                owners = np.array([c.robot for c in batch])
                self._apply(batch[0].kind, self._drone_of[owners], batch, owners, now, refusals)
        return refusals

    def _apply(self, kind: str, drones: np.ndarray, batch: list[DroneCommand], owners: np.ndarray, now: float,
               refusals: list[Refusal]) -> None:
        """One firmware call for ``drones``: ``batch`` has one command per drone, or one for all of
        them (the swarm's); ``owners``: the drones' robot indices."""
        try:
            problem = _problem(kind, batch)
            if problem is not None:
                raise ValueError(problem)
            if kind in STREAMS:
                self._stream(kind, drones, np.array([c.args for c in batch], dtype=np.float64), now)
                return
            if kind == "go_to":
                keep = self._in_arena(drones, batch, owners, refusals)
                if not keep.any():
                    return
                drones, owners = drones[keep], owners[keep]
                batch = batch if len(batch) == 1 else [c for c, k in zip(batch, keep) if k]
            codes = getattr(self, f"_{kind}")(drones, batch, now)
        except (ValueError, IndexError) as e:
            refusals += [Refusal(int(robot), f"{kind}: {e}") for robot in owners]
            return
        if codes is None:
            return
        for i in np.flatnonzero(np.atleast_1d(codes) != 0):
            code = int(codes[i])
            reason = _PLANNER.get(kind, "") if code == 1 else ""
            refusals.append(Refusal(int(owners[i]), f"{kind}: {_CODES.get(code, f'code {code}')}"
                                                    f"{': ' + reason if reason else ''}"))

    # --- streamed setpoints: one call for every drone that got one ------------------------------

    def _stream(self, kind: str, drones: np.ndarray, v: np.ndarray, now: float) -> None:
        fleet = self.fleet
        if kind == "full_state":
            fleet.cmd_full_state(drones, now, v[:, 0:3], v[:, 3:6], v[:, 6:9], v[:, 9], v[:, 10:13])
        elif kind == "position":
            fleet.cmd_position(drones, now, v[:, 0:3], v[:, 3])
        elif kind == "hover":
            fleet.cmd_hover(drones, now, v[:, 0], v[:, 1], v[:, 2], v[:, 3])
        elif kind == "velocity_world":
            fleet.cmd_velocity_world(drones, now, v[:, 0:3], v[:, 3])
        else:
            fleet.cmd_attitude(drones, now, v[:, 0], v[:, 1], v[:, 2], v[:, 3])

    # --- high-level commands (the services); a batch shares its group mask and flags ------------

    @staticmethod
    def _column(batch, i: int) -> np.ndarray:
        return np.array([c.args[i] for c in batch], dtype=np.float64)

    def _takeoff(self, drones, batch, now):
        # Crazyswarm2's servers take off and land turning to yaw 0 (their requests have no yaw).
        return self.fleet.takeoff(drones, now, self._column(batch, 0), self._column(batch, 1), yaw=0.0,
                                  group_mask=batch[0].args[2])

    def _land(self, drones, batch, now):
        return self.fleet.land(drones, now, self._column(batch, 0), self._column(batch, 1), yaw=0.0,
                               group_mask=batch[0].args[2])

    def _go_to(self, drones, batch, now):
        goal = np.array([c.args[0:3] for c in batch], dtype=np.float64)
        return self.fleet.go_to(drones, now, goal, self._column(batch, 3), self._column(batch, 4),
                                relative=bool(batch[0].args[5]), group_mask=batch[0].args[6])

    def _start_trajectory(self, drones, batch, now):
        trajectory_id, _, reversed_, relative, group_mask = batch[0].args
        codes = self.fleet.start_trajectory(drones, now, trajectory_id, timescale=self._column(batch, 1),
                                            reversed=bool(reversed_), relative=bool(relative), group_mask=group_mask)
        undefined = self.fleet.in_group(drones, group_mask) & ~self.fleet.high_level.memory.is_defined(drones,
                                                                                                       trajectory_id)
        return np.where(undefined & (codes == 0), UNDEFINED, codes)

    def _upload_trajectory(self, drones, batch, now):
        trajectory_id, offset, coefficients, durations = batch[0].args     # one drone's (_batch_key)
        return self.fleet.upload_trajectory(drones, trajectory_id, offset, coefficients, durations)

    def _notify_setpoints_stop(self, drones, batch, now):
        self.fleet.notify_setpoints_stop(drones)      # the firmware's meta-command has no group mask

    def _stop(self, drones, batch, now):
        return self.fleet.stop(drones, group_mask=batch[0].args[0])

    def _emergency(self, drones, batch, now):
        self.fleet.emergency(drones)

    def _arm(self, drones, batch, now):
        self.fleet.arm(drones, bool(batch[0].args[0]))

    def _set_group_mask(self, drones, batch, now):
        self.fleet.set_group_mask(drones, batch[0].args[0])

    # --- what no drone should be asked ----------------------------------------------------------

    def _in_arena(self, drones, batch, owners, refusals) -> np.ndarray:
        """[d] bool: the go-tos whose goal (a relative one: from the drone's current setpoint) is
        inside the arena; the others are refused."""
        goal = np.array([c.args[0:3] for c in batch], dtype=np.float64).reshape(-1, 3)
        goal = np.broadcast_to(goal, (len(drones), 3))
        if batch[0].args[5]:
            goal = goal + self.fleet.high_level.pos[drones]
        keep = np.asarray(self._inside(goal[:, :2]), dtype=bool).reshape(len(drones))
        refusals += [Refusal(int(owners[i]), f"go_to: the goal ({goal[i, 0]:.3f}, {goal[i, 1]:.3f}, "
                                             f"{goal[i, 2]:.3f}) m is outside the arena: refused")
                     for i in np.flatnonzero(~keep)]
        return keep


def _batch_key(command: DroneCommand) -> tuple:
    """What the commands applied in one call share: their kind, and a high-level command's group
    mask and flags (a stream's values are per drone)."""
    if command.kind in STREAMS:
        return (command.kind,)
    if command.kind == "upload_trajectory":
        return (command.kind, command.robot)
    if command.kind in ("go_to", "start_trajectory"):
        fixed = (5, 6) if command.kind == "go_to" else (0, 2, 3, 4)
        return (command.kind, *(command.args[i] for i in fixed))
    if command.kind in ("takeoff", "land"):
        return (command.kind, command.args[2])
    return (command.kind, *command.args)


def _problem(kind: str, batch: list[DroneCommand]) -> Optional[str]:
    """Why the commands of ``batch`` may not be applied (the same for every one of a batch but an
    upload's, which is one command), or None."""
    if kind not in KINDS:
        return f"no such command (known: {', '.join(KINDS)})"
    if kind in ("takeoff", "land", "go_to"):
        at = {"takeoff": 1, "land": 1, "go_to": 4}[kind]
        if any(not c.args[at] > 0 for c in batch):
            return "its duration must be positive"
    if kind == "upload_trajectory":
        durations = np.asarray(batch[0].args[3], dtype=np.float64).reshape(-1)
        if durations.size == 0:
            return "a trajectory with no pieces: refused"
        if not (durations > 0).all():
            return f"a piece of non-positive duration ({durations.min():g} s): refused"
        if np.asarray(batch[0].args[2]).shape != (durations.size, 4, 8):
            return "each piece has 8 coefficients for each of x, y, z and yaw"
    return None
