"""Crazyswarm2's services and setpoint topics of a drone, and what each request or message asks of
its firmware: a command's kind and arguments (core/drone_commands.py), in SI units and radians.

Their types are ``crazyflie_interfaces``'s, a package not on PyPI: composed_sim ships its own
definitions (the same names and fields, so the type hashes), built on first use, and a user's own
build of Crazyswarm2's comes first (docs/crazyflie.md). ``load()`` finds it, or says it is not there.

What each carries, as Crazyswarm2's C++ server hands it to the firmware:

- ``takeoff``, ``land``: height (m), duration, group mask (the servers turn to yaw 0);
- ``go_to``: goal (m), yaw (rad, as ``crazyflie_py`` sends it; the .srv's comment says degrees),
  duration, relative, group mask; ``all/go_to`` is always relative, as Crazyswarm2's broadcast is;
- ``upload_trajectory``: pieces of 8 coefficients per coordinate and a duration each;
- ``start_trajectory``, ``notify_setpoints_stop``, ``emergency`` (std_srvs/Empty), ``arm``;
- ``cmd_full_state`` (the yaw of its orientation), ``cmd_position`` (yaw in rad), ``cmd_hover``
  (body-frame m/s, yaw rate rad/s counter-clockwise, height), ``cmd_velocity_world``;
- ``cmd_vel_legacy`` (geometry_msgs/Twist): roll = linear.y and pitch = linear.x (degrees), yaw
  rate angular.z (deg/s), thrust linear.z (0-60000), which the server and the firmware turn into
  REP-103's angles: roll as given, pitch as given (the server's and the firmware's inversions
  cancel), the yaw rate negated (the firmware's legacy negation).
"""
from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from composed_sim.world.crazyflies import MESSAGE_PACKAGE as PACKAGE

LEGACY_MAX_THRUST = 60000           # the C++ server's clamp of cmd_vel_legacy's thrust


def _seconds(duration) -> float:
    return duration.sec + duration.nanosec * 1e-9


def _takeoff(r):
    return "takeoff", (float(r.height), _seconds(r.duration), int(r.group_mask))


def _land(r):
    return "land", (float(r.height), _seconds(r.duration), int(r.group_mask))


def _go_to(r, relative: Optional[bool] = None):
    g = r.goal
    return "go_to", (g.x, g.y, g.z, float(r.yaw), _seconds(r.duration),
                     bool(r.relative if relative is None else relative), int(r.group_mask))


def _upload(r):
    pieces = r.pieces
    try:
        coefficients = np.array([[p.poly_x, p.poly_y, p.poly_z, p.poly_yaw] for p in pieces],
                                dtype=np.float64).reshape(len(pieces), 4, -1)
    except ValueError:                     # pieces of different lengths
        coefficients = np.zeros((len(pieces), 4, 0))
    durations = np.array([_seconds(p.duration) for p in pieces], dtype=np.float64)
    return "upload_trajectory", (int(r.trajectory_id), int(r.piece_offset), coefficients, durations)


def _start(r):
    return "start_trajectory", (int(r.trajectory_id), float(r.timescale), bool(r.reversed), bool(r.relative),
                                int(r.group_mask))


def _notify(r):
    return "notify_setpoints_stop", (int(r.remain_valid_millisecs), int(r.group_mask))


def _full_state(m):
    p, q, v, w, a = m.pose.position, m.pose.orientation, m.twist.linear, m.twist.angular, m.acc
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return "full_state", (p.x, p.y, p.z, v.x, v.y, v.z, a.x, a.y, a.z, yaw, w.x, w.y, w.z)


def _legacy(m):
    rad = math.pi / 180.0
    thrust = min(max(m.linear.z, 0.0), LEGACY_MAX_THRUST)
    return "attitude", (m.linear.y * rad, m.linear.x * rad, -m.angular.z * rad, thrust)


# Per drone: service name → (its type's module and name, what a request asks).
SERVICES: dict[str, tuple[str, str, Callable]] = {
    "emergency": ("std_srvs.srv", "Empty", lambda r: ("emergency", ())),
    "takeoff": (f"{PACKAGE}.srv", "Takeoff", _takeoff),
    "land": (f"{PACKAGE}.srv", "Land", _land),
    "go_to": (f"{PACKAGE}.srv", "GoTo", _go_to),
    "upload_trajectory": (f"{PACKAGE}.srv", "UploadTrajectory", _upload),
    "start_trajectory": (f"{PACKAGE}.srv", "StartTrajectory", _start),
    "notify_setpoints_stop": (f"{PACKAGE}.srv", "NotifySetpointsStop", _notify),
    "arm": (f"{PACKAGE}.srv", "Arm", lambda r: ("arm", (bool(r.arm),))),
}
# The swarm's (``all/<name>`` of the crazyflie_server): the broadcasts Crazyswarm2's server offers.
SWARM_SERVICES: dict[str, tuple[str, str, Callable]] = {
    "takeoff": SERVICES["takeoff"], "land": SERVICES["land"],
    "go_to": (f"{PACKAGE}.srv", "GoTo", lambda r: _go_to(r, relative=True)),
    "start_trajectory": SERVICES["start_trajectory"], "notify_setpoints_stop": SERVICES["notify_setpoints_stop"],
    "arm": SERVICES["arm"], "emergency": SERVICES["emergency"],
}
# Per drone: setpoint topic → (its type's module and name, what a message asks).
SETPOINTS: dict[str, tuple[str, str, Callable]] = {
    "cmd_full_state": (f"{PACKAGE}.msg", "FullState", _full_state),
    "cmd_position": (f"{PACKAGE}.msg", "Position", lambda m: ("position", (m.x, m.y, m.z, m.yaw))),
    "cmd_hover": (f"{PACKAGE}.msg", "Hover", lambda m: ("hover", (m.vx, m.vy, m.yaw_rate, m.z_distance))),
    "cmd_velocity_world": (f"{PACKAGE}.msg", "VelocityWorld",
                           lambda m: ("velocity_world", (m.vel.x, m.vel.y, m.vel.z, m.yaw_rate))),
    "cmd_vel_legacy": ("geometry_msgs.msg", "Twist", _legacy),
}
STATUS = "status"
STATUS_PERIOD_S = 1.0        # Crazyswarm2's default status rate (its firmware_logging's 1 Hz)


@dataclass(frozen=True)
class Interfaces:
    """The classes of Crazyswarm2's interfaces, by the tables' keys."""
    services: dict[str, type]
    swarm_services: dict[str, type]
    setpoints: dict[str, type]
    status: type


def load() -> Optional[Interfaces]:
    """Crazyswarm2's interface classes, or None where ``crazyflie_interfaces`` is not importable."""
    try:
        def classes(table):
            return {name: getattr(importlib.import_module(module), cls) for name, (module, cls, _) in table.items()}
        return Interfaces(classes(SERVICES), classes(SWARM_SERVICES), classes(SETPOINTS),
                          importlib.import_module(f"{PACKAGE}.msg").Status)
    except (ImportError, AttributeError):
        return None


MISSING = (f"the drones have no Crazyswarm2 services or setpoint topics: the {PACKAGE} package is not "
           f"built (build it from Crazyswarm2's source with `composed-sim interfaces build "
           f"<crazyswarm2>/{PACKAGE}` and name it in the world file's interfaces, or on PYTHONPATH: "
           f"docs/crazyflie.md)")
