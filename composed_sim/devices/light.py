"""Light: the light ring, ARGoS's ``footbot_light_rotzonly_sensor.cpp`` (docs/architecture.md,
"Light ring"), over all robots at once.

``/<r>/light``, sensor_msgs/LaserScan in base_link: intensities = the reading in [0, 1] per sensor
at the ring's angles; ranges empty. A controller's Tick: ``light``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, reads_into
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.common.poses import wrap_angle
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import (_check_noise, _observer_rows, _robots, _uniform_noise, blocked_by_robots,
                                                 kd_tree)
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import Topic, base_link

NAME = "light"


@dataclass(frozen=True)
class LightRing:
    angles_rad: tuple[float, ...]   # [k] CCW from the front


class LightConfig(DeviceSwitch):
    noise: NonNegativeFloat = 0.0


# footbot_light_rotzonly_sensor.cpp: a light lights the nearest sensor and 6 on either side.
_LIGHT_HALF_WINDOW = 6


def light_ring(positions, headings, radii, heights, ring: LightRing, lights: Sequence[Any],
               scene: StaticScene, *, noise: float = 0.0, rng: Optional[np.random.Generator] = None,
               tree: Optional[cKDTree] = None, observers=None) -> np.ndarray:
    """positions [n, 2], headings [n], radii [n], heights [n] → readings [n, k] in [0, 1]
    (or [m, k] for the robots ``observers`` [m] only; all robots can block the light); ``lights``: the
    world file's (position, height_m, intensity).

    For each light with intensity I > 0 whose ray from the robot's origin on the floor (z = 0)
    to the light is not blocked by another robot or a static body: d' = (3D distance) / I,
    base = exp(-2 d') if d' <= 2.5 else 0, and the nearest sensor and 6 on either side get
    base * max(0, 1 - 2Δ/π), Δ the angle between the light's bearing and the sensor. Lights
    add; uniform noise; clamp to [0, 1] (ARGoS footbot_light_rotzonly_sensor.cpp, which takes
    the length of the 3D robot-to-light vector).
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    _check_noise("noise", noise, rng)
    observers, _ = _observer_rows(observers, len(positions))
    everyone = np.arange(len(positions)) if observers is None else observers             # [m]
    n = len(everyone)
    sensor = np.asarray(ring.angles_rad)                                                 # [k]
    k = len(sensor)
    out = np.zeros((n, k))
    lights = [lt for lt in lights if lt.intensity > 0.0]
    if n == 0 or not lights:
        return _uniform_noise(out, noise, rng)
    tree = kd_tree(positions) if tree is None else tree
    origin = np.column_stack([positions[everyone], np.zeros(n)])                         # [m, 3]
    obs_head = headings if observers is None else headings[everyone]
    for light in lights:
        target = np.array([light.position[0], light.position[1], light.height_m])
        to_light = target - origin                                                       # [n, 3]
        reduced = np.linalg.norm(to_light, axis=1) / light.intensity
        idx = np.flatnonzero(reduced <= 2.5)       # beyond 2.5 the light adds nothing: skip the ray
        p0, p1 = origin.take(idx, axis=0), np.broadcast_to(target, (len(idx), 3))
        blocked = scene.blocks(p0, p1) | blocked_by_robots(p0, p1, everyone[idx], np.full(len(idx), -1),
                                                           positions, radii, heights, tree)
        idx = idx[~blocked]
        bearing = np.arctan2(to_light[idx, 1], to_light[idx, 0]) - obs_head[idx]
        delta = np.abs(wrap_angle(bearing[:, None] - sensor[None, :]))                 # [m, k]
        nearest = np.argmin(delta, axis=1)
        off = (np.arange(k)[None, :] - nearest[:, None]) % k
        # With 24 sensors 15° apart the sensors outside the window are > 90° away and would
        # weigh 0 anyway; the window matters for other layouts (and never adds twice).
        window = np.minimum(off, k - off) <= _LIGHT_HALF_WINDOW
        weight = np.where(window, np.maximum(0.0, 1.0 - 2.0 * delta / math.pi), 0.0)
        out[idx] += np.exp(-2.0 * reduced[idx])[:, None] * weight
    return _uniform_noise(out, noise, rng)


def read(s: Sensing, group: SensedGroup, out) -> None:
    out.light = light_ring(s.positions, s.headings, s.radii, s.heights, group.model.light, s.lights, s.scene,
                           noise=group.settings.config(NAME).noise, rng=s.noise(NAME, group), tree=s.tree,
                           observers=s.observers(group))


# --- its topic ------------------------------------------------------------------------------------

TOPIC = Topic("light", "sensor_msgs/msg/LaserScan", "sensor",
              "light ring: intensities = reading in [0, 1] per sensor; ranges empty")


def encoder(ring: LightRing, robot: str) -> cdr.ScanEncoder:
    return cdr.ScanEncoder(cdr.ring_scan_bytes(base_link(robot), ring.angles_rad, 0.0, 0, len(ring.angles_rad)))


def decode(data: bytes) -> np.ndarray:
    """A scan's bytes → readings [k] in [0, 1]."""
    return cdr.decode_scan_intensities(data)


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.models[i].light, robots.names[i])

    def publish(self, plan, frame, out):
        self.send_scans(plan, out, None, frame.groups[plan.group].light[plan.within])


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into("light", decode), tick_fields=("light",),
                settings=LightConfig, layout=LightRing, read=read, readings=("light",))
