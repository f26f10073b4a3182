"""Light: the light ring, over all robots at once, read by one of ARGoS's light sensor elements.

The ring (where the sensors are) belongs to the robot; the reading model is the sensor's, as in
ARGoS, where each sensor element computes its own readings from the same ring:

- ``foot-bot``: ``footbot_light`` (``footbot_light_rotzonly_sensor.cpp``, docs/architecture.md
  "Light ring"): one ray from the robot's origin to each light; the light's reduced distance
  d' = d / I gives exp(-2 d') (0 beyond 2.5), spread over the sensor nearest the light's bearing
  and 6 on either side, weighted by max(0, 1 - 2Δ/π).
- ``kheperaiv``: ``kheperaiv_light`` (the Khepera IV plugin's ``kheperaiv_light_rotzonly_sensor.cpp``):
  the same reading, but its index arithmetic is the foot-bot's (the light's bearing divided by 15°,
  rounded half away from zero), taken modulo 8, and only that index and 2 on either side get it.
- ``generic``: ``light`` (``light_default_sensor.cpp``): each sensor casts its own ray from its
  place on the rim to each light; the light counts I² / d² (d from the sensor) unless something,
  the robot's own body included, is in the way. The own body hides every light behind the
  sensor's tangent plane (the ray starts on the body's circle and enters it).

A world file picks it with ``devices: {light: {model: generic}}``; the default is the robot's
own (``LightRing.model``): the foot-bot's and the Khepera IV's rotzonly sensors, the generic one for
the e-puck, which has no light sensor element of its own in ARGoS.

``/<r>/light``, sensor_msgs/LaserScan in base_link: intensities = the reading in [0, 1] per sensor
at the ring's angles; ranges empty. A controller's Tick: ``light``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal, Optional, Sequence

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


# The light sensor elements of ARGoS this module models (the module docstring says each).
LightModel = Literal["foot-bot", "kheperaiv", "generic"]


@dataclass(frozen=True)
class LightRing:
    angles_rad: tuple[float, ...]   # [k] CCW from the front
    elevation_m: float = 0.0        # the sensors' height on the rim (the generic model's rays start there)
    model: LightModel = "foot-bot"  # the robot's own light sensor element


class LightConfig(DeviceSwitch):
    noise: NonNegativeFloat = 0.0
    # The reading model (which ARGoS sensor element reads the ring); None: the robot's own.
    model: Optional[LightModel] = None


# footbot_light_rotzonly_sensor.cpp: a light lights the nearest sensor and 6 on either side.
_LIGHT_HALF_WINDOW = 6
# kheperaiv_light_rotzonly_sensor.cpp: the index of the foot-bot's 15° spacing, modulo 8, ± 2.
_KHEPERAIV_SPACING_RAD = math.pi / 12.0
_KHEPERAIV_HALF_WINDOW = 2


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
    if ring.model == "generic":
        _generic_readings(out, positions, headings, radii, heights, ring, lights, scene, everyone, tree)
        return _uniform_noise(out, noise, rng)
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
        if ring.model == "kheperaiv":
            # Its index counts 15° steps (the foot-bot's), rounded half away from zero, modulo 8.
            steps = wrap_angle(bearing) / _KHEPERAIV_SPACING_RAD
            nearest = np.trunc(steps + np.where(steps > 0, 0.5, -0.5)).astype(np.intp) % k
            half_window = _KHEPERAIV_HALF_WINDOW
        else:
            nearest = np.argmin(delta, axis=1)
            half_window = _LIGHT_HALF_WINDOW
        off = (np.arange(k)[None, :] - nearest[:, None]) % k
        # With 24 sensors 15° apart the sensors outside the window are > 90° away and would
        # weigh 0 anyway; the window matters for other layouts (and never adds twice).
        window = np.minimum(off, k - off) <= half_window
        weight = np.where(window, np.maximum(0.0, 1.0 - 2.0 * delta / math.pi), 0.0)
        out[idx] += np.exp(-2.0 * reduced[idx])[:, None] * weight
    return _uniform_noise(out, noise, rng)


def _generic_readings(out, positions, headings, radii, heights, ring: LightRing, lights, scene: StaticScene,
                      everyone: np.ndarray, tree: cKDTree) -> None:
    """ARGoS's generic light sensor into ``out`` [m, k]: per sensor and light, I² / d² from the
    sensor on the rim (at ``ring.elevation_m``) to the light, unless a static body, another robot
    or the robot's own body (any light behind the sensor's tangent) is in the way."""
    n, k = out.shape
    angles = headings[everyone][:, None] + np.asarray(ring.angles_rad)[None, :]           # [m, k]
    normal = np.stack([np.cos(angles), np.sin(angles)], axis=-1)                          # [m, k, 2]
    rim = positions[everyone][:, None, :] + radii[everyone][:, None, None] * normal       # [m, k, 2]
    p0 = np.concatenate([rim, np.full((n, k, 1), ring.elevation_m)], axis=-1).reshape(-1, 3)
    owner = np.repeat(everyone, k)
    for light in lights:
        target = np.array([light.position[0], light.position[1], light.height_m])
        to_light = target - p0                                                             # [m k, 3]
        facing = np.einsum("ij,ij->i", to_light[:, :2], normal.reshape(-1, 2)) >= 0.0
        idx = np.flatnonzero(facing)
        q0, q1 = p0.take(idx, axis=0), np.broadcast_to(target, (len(idx), 3))
        blocked = scene.blocks(q0, q1) | blocked_by_robots(q0, q1, owner[idx], np.full(len(idx), -1),
                                                           positions, radii, heights, tree)
        idx = idx[~blocked]
        squared = np.einsum("ij,ij->i", to_light[idx], to_light[idx])
        with np.errstate(divide="ignore"):
            out.reshape(-1)[idx] += light.intensity ** 2 / squared
    np.clip(out, 0.0, 1.0, out=out)


def ring_for(ring: LightRing, model: Optional[str]) -> LightRing:
    """The ring read by the reading model ``model`` (None: its own)."""
    return ring if model is None or model == ring.model else replace(ring, model=model)


def read(s: Sensing, group: SensedGroup, out) -> None:
    out.light = light_ring(s.positions, s.headings, s.radii, s.heights,
                           ring_for(group.model.light, group.settings.config(NAME).model), s.lights, s.scene,
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
        places, rows = self.to_send(plan, out)
        if rows:
            self.send_scans(places, rows, out, None, frame.groups[plan.group].light[plan.within],
                            hand=lambda ranges, intensities: intensities.__getitem__)   # decode's reading


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into("light", decode), tick_fields=("light",),
                settings=LightConfig, layout=LightRing, read=read, readings=("light",))
